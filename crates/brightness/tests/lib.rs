//! Integration tests of `brightness` (the end-to-end finite-difference check of `L_I`
//! against the renderer lives in `pgm`'s pipeline tests, beside `L_G`'s).

mod feature;
