//! Photometric Gaussian mixtures of omnidirectional images and their Jacobians.
//!
//! **Not implemented yet**: this crate has no API until issue #4 lands (see
//! `docs/ARCHITECTURE.md` for what it will hold). It exists so that the workspace has
//! its final shape and the crate name is reserved.
#![deny(missing_docs)]
