//! Stage timers for `pixguide bench-denoise`: the wall seconds and the multiply-accumulates of
//! each stage of a run (convolutions, kernel application per scale, …), so the bench can print
//! each stage's share and its achieved GMAC/s. Off unless a caller [`start`]s it; recording is
//! then one lock per stage call (a handful per window), not per pixel.

use std::sync::Mutex;
use std::time::Instant;

/// One stage's totals.
#[derive(Clone, Debug, PartialEq)]
pub struct Stage {
    pub name: String,
    pub seconds: f64,
    pub macs: f64,
    pub calls: usize,
}

static STAGES: Mutex<Option<Vec<Stage>>> = Mutex::new(None);

/// Starts (or restarts) recording, with no stages yet.
pub fn start() {
    *STAGES.lock().unwrap_or_else(|e| e.into_inner()) = Some(Vec::new());
}

/// Stops recording and returns the stages in the order they first ran.
pub fn take() -> Vec<Stage> {
    STAGES.lock().unwrap_or_else(|e| e.into_inner()).take().unwrap_or_default()
}

/// Adds `seconds` and `macs` to stage `name` if recording.
pub fn record(name: &str, seconds: f64, macs: f64) {
    if let Some(stages) = STAGES.lock().unwrap_or_else(|e| e.into_inner()).as_mut() {
        match stages.iter_mut().find(|s| s.name == name) {
            Some(s) => {
                s.seconds += seconds;
                s.macs += macs;
                s.calls += 1;
            }
            None => stages.push(Stage { name: name.to_string(), seconds, macs, calls: 1 }),
        }
    }
}

/// Whether a run is being recorded (callers skip computing names and MAC counts otherwise).
pub fn active() -> bool {
    STAGES.lock().unwrap_or_else(|e| e.into_inner()).is_some()
}

/// Runs `f`, recording its wall time under `name` with `macs` multiply-accumulates.
pub fn timed<T>(name: impl FnOnce() -> String, macs: f64, f: impl FnOnce() -> T) -> T {
    if !active() {
        return f();
    }
    let t = Instant::now();
    let out = f();
    record(&name(), t.elapsed().as_secs_f64(), macs);
    out
}
