//! `pixguide sky`: write a procedural daylight environment map (Preetham sky + sun) to EXR.

use anyhow::Result;
use clap::Args;
use renderer::sky::{bake, SkyParams};
use std::path::PathBuf;

#[derive(Args)]
pub struct SkyArgs {
    /// Output EXR (lat-long, +Y up; see docs/scene-format.md).
    #[arg(short, long, default_value = "sky.exr")]
    pub output: PathBuf,
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// Sun elevation above the horizon, degrees.
    #[arg(long, default_value_t = 35.0)]
    pub elevation: f32,
    /// Sun azimuth, degrees (0 = −Z, 90 = +X).
    #[arg(long, default_value_t = 40.0)]
    pub azimuth: f32,
    /// Turbidity, 2 (clear) … 10 (hazy).
    #[arg(long, default_value_t = 3.0)]
    pub turbidity: f32,
    /// Sun irradiance / sky irradiance on the ground.
    #[arg(long, default_value_t = 4.0)]
    pub sun_to_sky: f32,
}

pub fn run(a: SkyArgs) -> Result<()> {
    let p = SkyParams {
        width: a.width,
        height: a.width / 2,
        sun_elevation_deg: a.elevation,
        sun_azimuth_deg: a.azimuth,
        turbidity: a.turbidity,
        sun_to_sky: a.sun_to_sky,
        ..Default::default()
    };
    let tex = bake(&p);
    renderer::film::exr_io::write_rgb(&a.output, &tex)?;
    println!("wrote {} ({}x{})", a.output.display(), tex.width, tex.height);
    Ok(())
}
