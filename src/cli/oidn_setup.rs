//! Intel Open Image Denoise for `eval`, `render --denoise oidn` and `denoise --model oidn`.
//!
//! The library comes from the pyoidn wheel on PyPI, which ships `libOpenImageDenoise.so.2` with
//! its core library, CPU device module and TBB. It is installed into a venv under `target/` the
//! first time it is needed, through the same helper as Embree's venv for the BVH cross-check
//! (`tools_venv::tools_venv`, tools/venv/). Python is only the installer: the denoising runs in
//! this process (`denoiser::oidn`, dlopen of the wheel's library).

use anyhow::{Context, Result};
use denoiser::infer::{Denoised, Timings};
use denoiser::oidn::Oidn;
use renderer::film::Frame;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The wheel, pinned: its library is OIDN 2.5.1.
pub const PACKAGE: &str = "pyoidn==2.5.1.0";

/// Prints the wheel's library folder without importing pyoidn (whose import needs numpy and
/// cffi, which the Rust side does not), failing if the library is not in it.
const PROBE: &str = "import importlib.util, os\n\
spec = importlib.util.find_spec('pyoidn')\n\
d = os.path.join(spec.submodule_search_locations[0], 'oidn', 'lib')\n\
assert os.path.isfile(os.path.join(d, 'libOpenImageDenoise.so.2')), d + ' has no libOpenImageDenoise.so.2'\n\
print(d)";

/// `PIXGUIDE_OIDN_VENV` when set (a venv kept elsewhere, e.g. by a CI cache), else
/// `target/oidn-venv` of the source tree this binary was built from (like the shipped weights'
/// default), or of the current folder when that tree is gone.
pub fn venv_dir() -> PathBuf {
    if let Some(v) = std::env::var_os("PIXGUIDE_OIDN_VENV").filter(|v| !v.is_empty()) {
        return PathBuf::from(v);
    }
    let built = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = if built.is_dir() { built } else { Path::new(".") };
    root.join("target/oidn-venv")
}

/// The folder holding `libOpenImageDenoise.so.2`, installing the wheel first if needed.
pub fn library_dir() -> Result<PathBuf> {
    let venv = venv_dir();
    let v = tools_venv::tools_venv(&venv, &[PACKAGE], PROBE).with_context(|| format!("installing Open Image Denoise (pip {PACKAGE})"))?;
    Ok(PathBuf::from(v.probe))
}

/// Installs (first time) and loads OIDN with a CPU device on as many threads as ours. Returns
/// it with the wall seconds this took: a one-time cost per process, not a per-frame one.
pub fn load() -> Result<(Oidn, f64)> {
    let t = Instant::now();
    let dir = library_dir()?;
    let oidn = Oidn::load(&dir, rayon::current_num_threads())?;
    Ok((oidn, t.elapsed().as_secs_f64()))
}

/// Identity of the method in eval's cache: the library version and the filter settings, in the
/// place of a weight file's hash.
pub fn method_id(oidn: &Oidn) -> String {
    format!("oidn-{}:rt,hdr,quality-high,albedo,normal", oidn.version())
}

/// What the method is, for the results page and the command line.
pub fn describe(oidn: &Oidn) -> String {
    format!(
        "OIDN {} (pip `{PACKAGE}`), RT filter, hdr, quality high, CPU device with {} threads; inputs: noisy radiance and our albedo and normal G-buffers",
        oidn.version(),
        oidn.threads()
    )
}

/// Denoises a frame's radiance with its albedo and normal G-buffers. `timings.total_s` is the
/// wall time of the filter (commit + execute).
pub fn denoise_frame(oidn: &Oidn, frame: &Frame) -> Result<Denoised> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let albedo = frame.albedo.as_ref().context("OIDN needs the albedo G-buffer, and the frame has none (render with --aovs)")?;
    let normal = frame.normal.as_ref().context("OIDN needs the normal G-buffer, and the frame has none (render with --aovs)")?;
    let t = Instant::now();
    let radiance = oidn.denoise(&frame.radiance.mean, &albedo.mean, &normal.mean, w, h)?;
    let timings = Timings { total_s: t.elapsed().as_secs_f64(), ..Default::default() };
    Ok(Denoised { width: w, height: h, radiance, weights_g: None, timings })
}

pub fn print_summary(oidn: &Oidn, load_s: f64, d: &Denoised) {
    println!(
        "denoise (OIDN {}, RT filter, hdr, quality high, {} threads): {:.2} s for the filter's commit + execute; before it, {load_s:.2} s to load the library and create the device (once)",
        oidn.version(),
        oidn.threads(),
        d.timings.total_s
    );
}

/// [`denoise_frame`], after one untimed run the first time (`warm` false): the first execution
/// on a fresh device also pays one-off costs (starting its worker threads, first touch of the
/// weights) that belong to no frame.
pub fn denoise_timed(oidn: &Oidn, frame: &Frame, warm: &mut bool) -> Result<Denoised> {
    if !*warm {
        denoise_frame(oidn, frame)?;
        *warm = true;
    }
    denoise_frame(oidn, frame)
}
