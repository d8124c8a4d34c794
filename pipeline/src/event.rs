//! What a run tells as it goes: the events its consumers read (the report, the command line's
//! progress, any caller of [`crate::run()`]), as brush's process messages. The run drives the
//! frames and emits; it neither draws progress nor assembles the report itself.

use std::collections::BTreeMap;

use crate::config::Method;
use crate::records::{FailedFrame, FrameEntry, FrameRecord};
use crate::report::model::Report;

/// One thing a run tells, in the order it happens: notices, `Started`, then per frame in frame
/// order its methods' results and either `FrameDone` or `FrameFailed`, then `Finishing`.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Something the user should know before the frames run, told once (a weights track's
    /// channels that drive nothing, a run being resumed).
    Notice(String),
    /// Inputs read: what the run is, and how many frames it goes through.
    Started {
        /// Frames to go through (those a resumed run already did included).
        frames: usize,
        /// The report as the run starts: what the run is (inputs, options, scale-derived
        /// parameters, the Gaussians used), no frame or method yet.
        report: Box<Report>,
        /// Each method's parameters, for the record (e.g. `voxel`, `alpha`, `views`).
        parameters: BTreeMap<Method, BTreeMap<String, f64>>,
        /// Template triangles: the incremental Delaunay's charts.
        charts: usize,
    },
    /// One method's mesh of one frame is written (not told for frames a resumed run did).
    MethodDone {
        /// The method.
        method: Method,
        /// Its record of the frame.
        record: Box<FrameRecord>,
    },
    /// One frame done, by this run or (`resumed`) by the run it resumes.
    FrameDone {
        /// Frames gone through so far, this one included.
        done: usize,
        /// Frames in all.
        total: usize,
        /// The frame's records, as the journal holds them.
        entry: FrameEntry,
        /// Done by the run being resumed (its files were found).
        resumed: bool,
    },
    /// One frame failed; the run goes on without it (unless it fails fast).
    FrameFailed {
        /// Frames gone through so far, this one included.
        done: usize,
        /// Frames in all.
        total: usize,
        /// The frame and the error.
        failure: FailedFrame,
    },
    /// Every frame gone through: the sequences, reports and plot are being written.
    Finishing,
}
