//! The crate's one logging shim: defmt when the `defmt` feature is on, nothing otherwise.

/// Logs a debug line through defmt, or compiles to nothing.
#[cfg(feature = "defmt")]
macro_rules! debug {
    ($($arg:tt)*) => { defmt::debug!($($arg)*) };
}

/// Logs a debug line through defmt, or compiles to nothing.
#[cfg(not(feature = "defmt"))]
macro_rules! debug {
    ($($arg:tt)*) => {{}};
}

#[allow(unused_imports)]
pub(crate) use debug;
