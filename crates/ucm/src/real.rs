//! A minimal floating-point abstraction, so that every formula of the model is written
//! once and instantiated in `f64` (accuracy, tests) and in `f32` (hot loops).

use std::fmt::Debug;

use crate::{Camera, intrinsics::Params};
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// `f32` or `f64`. Only what the camera model needs.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + Send
    + Sync
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// 2.
    const TWO: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Whether the value is neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// Conversion from `f64` (rounding for `f32`).
    fn from_f64(value: f64) -> Self;
    /// Conversion to `f64` (exact).
    fn to_f64(self) -> f64;
    /// Largest of two values (NaN-ignoring, as `f64::max`).
    fn max(self, other: Self) -> Self;
    /// The camera's parameters converted to this type (precomputed at construction).
    #[doc(hidden)]
    fn camera_params(camera: &Camera) -> &Params<Self>;
}

macro_rules! impl_real {
    ($t:ty, $field:ident) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const EPSILON: Self = <$t>::EPSILON;
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn from_f64(value: f64) -> Self {
                value as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            #[inline(always)]
            fn camera_params(camera: &Camera) -> &Params<Self> {
                &camera.$field
            }
        }
    };
}

impl_real!(f32, params_f32);
impl_real!(f64, params_f64);
