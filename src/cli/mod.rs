pub mod progress;
pub mod render;
pub mod font;
pub mod bench;
pub mod sky;
pub mod dataset;
pub mod reference;
pub mod denoise;
