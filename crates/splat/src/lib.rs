//! CPU point-cloud renderer for the unified central camera model.
//!
//! **Not implemented yet**: this crate has no API until issue #3 lands (see
//! `docs/ARCHITECTURE.md` for what it will hold). It exists so that the workspace has
//! its final shape and the crate name is reserved.
#![deny(missing_docs)]
