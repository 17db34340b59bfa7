//! Frames: what a render produces, in memory, and its files (EXR, PNG).
