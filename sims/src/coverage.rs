//! Coverage (helper in progress).
