//! Virtual visual servoing: PGM (Rule0, Rule1, Rule2) and PoVS pose optimisation.
//!
//! **Not implemented yet**: this crate has no API until issue #5 lands (see
//! `docs/ARCHITECTURE.md` for what it will hold). It exists so that the workspace has
//! its final shape and the crate name is reserved.
#![deny(missing_docs)]
