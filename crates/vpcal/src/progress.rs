//! Progress of long work, reported to whoever runs it (a terminal bar, a Python callback).

/// Where the pipeline stands after a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameProgress {
    /// Frames looked at so far (a replayed frame counts again).
    pub frames: u64,
    /// Seconds since the first frame.
    pub seconds: f64,
    /// Vehicle boxes that reached the network so far.
    pub vehicle_boxes: u64,
}

impl FrameProgress {
    /// Frames per second so far.
    pub fn frames_per_second(&self) -> f64 {
        self.frames as f64 / self.seconds.max(1e-9)
    }
}

/// Receives the pipeline's progress; every method has a no-op default.
pub trait Progress {
    /// Work starts; `frames` is the expected number of frames when known.
    fn start(&self, _frames: Option<u64>) {}
    /// `more` frames will be looked at again (the detector's warm-up).
    fn add_frames(&self, _more: u64) {}
    /// One more frame done.
    fn frame_done(&self, _at: &FrameProgress) {}
    /// Work is done.
    fn finish(&self) {}
}

/// No progress reports.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}
