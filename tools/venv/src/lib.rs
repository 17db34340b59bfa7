//! Python venvs holding the tools pixguide borrows: Embree's Python binding (the BVH
//! cross-check test and `pixguide bench`), Mitsuba 3 (the image cross-check test and `pixguide
//! bench`'s integrator comparison) and Open Image Denoise's library (the `oidn` baseline). A venv is built with `python3 -m venv` and pip the first time it is needed and
//! reused afterwards.
//!
//! This is the only code that creates venvs or runs pip. It is its own small crate so that the
//! renderer library stays free of it while the binary (`pixguide bench`, the OIDN setup) and
//! the renderer's Embree test and examples share one copy.

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What went wrong building or probing a venv, with the venv's path and the tool's last line
/// of error output.
#[derive(Debug)]
pub struct Error(String);

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;

/// A Python venv holding a tool pixguide borrows (Embree's binding, OIDN's library).
pub struct ToolsVenv {
    pub python: PathBuf,
    /// What the probe printed, trimmed.
    pub probe: String,
}

/// Returns the Python interpreter of the venv at `venv` with embreex and numpy installed,
/// creating the venv (python3 -m venv; pip install embreex numpy) if it does not work yet.
pub fn embree_python(venv: &Path) -> Result<PathBuf> {
    tools_venv(venv, &["embreex", "numpy"], "import embreex.rtcore_scene, numpy").map(|v| v.python)
}

/// The Mitsuba 3 release both the cross-check and the benchmark install: pinned, because the
/// cross-check's documented agreement and the benchmark's recorded figures are for this one.
pub const MITSUBA: &str = "mitsuba==3.9.1";

/// The venv at `venv` with Mitsuba 3 (`MITSUBA`) and numpy; `probe` of the result is Mitsuba's
/// version.
pub fn mitsuba_python(venv: &Path) -> Result<ToolsVenv> {
    tools_venv(venv, &[MITSUBA, "numpy"], "import mitsuba as mi, numpy; mi.set_variant('scalar_rgb'); print(mi.__version__)")
}

/// A libLLVM shared library for Dr.Jit's LLVM backend (Mitsuba's `llvm_*` variants), to pass as
/// `DRJIT_LIBLLVM_PATH`: the variable itself if it is set, else the newest versioned
/// `libLLVM*.so*` in the usual library folders. The newest, because Dr.Jit 1.5 emits
/// intrinsics that old LLVMs cannot compile for every CPU (LLVM 15 aborts on `fminimum` on an
/// AVX-512 machine) while Dr.Jit's own search takes the first it finds.
pub fn libllvm_for_drjit() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("DRJIT_LIBLLVM_PATH").filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(p));
    }
    let mut dirs: Vec<PathBuf> = [
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
        "/usr/lib64",
        "/usr/lib",
        "/usr/local/lib",
        "/opt/homebrew/opt/llvm/lib",
        "/usr/local/opt/llvm/lib",
    ]
    .iter()
    .map(PathBuf::from)
    .collect();
    // Debian/Ubuntu's per-version trees (/usr/lib/llvm-19/lib), Fedora's (/usr/lib64/llvm19/lib).
    for parent in ["/usr/lib", "/usr/lib64"] {
        if let Ok(rd) = std::fs::read_dir(parent) {
            dirs.extend(rd.flatten().filter(|e| e.file_name().to_string_lossy().starts_with("llvm")).map(|e| e.path().join("lib")));
        }
    }
    let mut best: Option<(u32, PathBuf)> = None;
    for dir in dirs {
        let Ok(rd) = std::fs::read_dir(&dir) else { continue };
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(major) = libllvm_major(&name) else { continue };
            if best.as_ref().is_none_or(|(m, _)| major > *m) {
                best = Some((major, e.path()));
            }
        }
    }
    best.map(|(_, p)| p)
}

/// The LLVM major version in a shared library's file name (`libLLVM-19.so`, `libLLVM.so.19.1`,
/// `libLLVM-14.0.6.so.1`, `libLLVM.dylib` has none).
fn libllvm_major(name: &str) -> Option<u32> {
    let rest = name.strip_prefix("libLLVM")?;
    if !(rest.contains(".so") || rest.ends_with(".dylib")) {
        return None;
    }
    let digits = |s: &str| s.chars().take_while(char::is_ascii_digit).collect::<String>().parse().ok();
    match rest.strip_prefix('-') {
        Some(v) => digits(v),
        None => rest.strip_prefix(".so.").and_then(digits),
    }
}

/// The venv at `venv` in which the Python snippet `probe` runs successfully, built (`python3 -m
/// venv --clear`, then `pip install packages`) when the venv is missing or the probe fails in
/// it: a half-finished install or a venv whose python3 went away is rebuilt rather than
/// patched. A lock file beside the venv (`<venv>.lock`) is held meanwhile, so that two processes
/// (a test and an eval, say) never build the same venv at once.
pub fn tools_venv(venv: &Path, packages: &[&str], probe: &str) -> Result<ToolsVenv> {
    let fail = |what: String, detail: &str| {
        Error(format!("Python venv {}: {what}{}{}", venv.display(), if detail.is_empty() { "" } else { ": " }, detail))
    };
    if let Some(dir) = venv.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| fail(format!("creating {}", dir.display()), &e.to_string()))?;
    }
    let lock_path = venv.with_extension("lock");
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock_path)
        .map_err(|e| fail(format!("opening {}", lock_path.display()), &e.to_string()))?;
    lock.lock().map_err(|e| fail(format!("locking {}", lock_path.display()), &e.to_string()))?;
    let python = venv.join("bin/python");
    let run_probe = || Command::new(&python).args(["-c", probe]).output();
    if let Ok(out) = run_probe() {
        if out.status.success() {
            return Ok(ToolsVenv { python, probe: String::from_utf8_lossy(&out.stdout).trim().to_string() });
        }
    }
    let out = Command::new("python3")
        .args(["-m", "venv", "--clear"])
        .arg(venv)
        .output()
        .map_err(|e| fail("python3 -m venv".into(), &e.to_string()))?;
    if !out.status.success() {
        return Err(fail("python3 -m venv failed".into(), &last_line(&out.stderr)));
    }
    let install = format!("pip install {}", packages.join(" "));
    let out = Command::new(venv.join("bin/pip"))
        .args(["install", "--quiet", "--disable-pip-version-check"])
        .args(packages)
        .output()
        .map_err(|e| fail(install.clone(), &e.to_string()))?;
    if !out.status.success() {
        return Err(fail(format!("{install} failed"), &last_line(&out.stderr)));
    }
    let out = run_probe().map_err(|e| fail(format!("running {}", python.display()), &e.to_string()))?;
    if !out.status.success() {
        return Err(fail(format!("{install} done, but the probe `{probe}` fails"), &last_line(&out.stderr)));
    }
    Ok(ToolsVenv { python, probe: String::from_utf8_lossy(&out.stdout).trim().to_string() })
}

/// The last non-empty line of a tool's error output: pip and Python put the actual error there,
/// after pages of context that would drown a one-line message.
fn last_line(stderr: &[u8]) -> String {
    String::from_utf8_lossy(stderr).lines().map(str::trim).rfind(|l| !l.is_empty()).unwrap_or("").to_string()
}

#[cfg(test)]
mod tests {
    use super::libllvm_major;

    #[test]
    fn llvm_versions_from_file_names() {
        assert_eq!(libllvm_major("libLLVM-19.so"), Some(19));
        assert_eq!(libllvm_major("libLLVM.so.19.1"), Some(19));
        assert_eq!(libllvm_major("libLLVM-14.0.6.so.1"), Some(14));
        assert_eq!(libllvm_major("libLLVM-15.so.1"), Some(15));
        assert_eq!(libllvm_major("libLLVM.so"), None);
        assert_eq!(libllvm_major("libLLVMSupport.a"), None);
        assert_eq!(libllvm_major("libLTO.so.19"), None);
    }
}
