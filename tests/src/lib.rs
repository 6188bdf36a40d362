//! troupe-tests: end-to-end tests across crates (see `tests/`), and the home of the
//! workspace examples (`examples/` at the repository root).
#![deny(missing_docs)]
