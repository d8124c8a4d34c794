//! One module per `trisplat` command: its arguments and its `run`.

pub mod convert;
pub mod eval;
pub mod sample;
pub mod smooth;

use crate::progress::Progress;

/// What every command gets besides its arguments.
#[derive(Clone, Copy, Debug)]
pub struct Context {
    /// Progress bar factory.
    pub progress: Progress,
}
