//! Camera (helper in progress).
