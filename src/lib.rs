//! Test and bench suite of vltm (no library code).
