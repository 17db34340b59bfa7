//! Python venvs holding the tools pixguide borrows: Embree's Python binding (the BVH
//! cross-check test and `pixguide bench`) and Open Image Denoise's library (the `oidn`
//! baseline). A venv is built with `python3 -m venv` and pip the first time it is needed and
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

/// The venv at `venv` in which the Python snippet `probe` runs successfully, built (`python3 -m
/// venv --clear`, then `pip install packages`) when the venv is missing or the probe fails in
/// it: a half-finished install or a venv whose python3 went away is rebuilt rather than
/// patched. A lock file beside the venv (`<venv>.lock`) is held meanwhile, so that two processes
/// (a test and an eval, say) never build the same venv at once.
pub fn tools_venv(venv: &Path, packages: &[&str], probe: &str) -> Result<ToolsVenv> {
    let fail = |what: String, detail: &str| Error(format!("Python venv {}: {what}{}{}", venv.display(), if detail.is_empty() { "" } else { ": " }, detail));
    if let Some(dir) = venv.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| fail(format!("creating {}", dir.display()), &e.to_string()))?;
    }
    let lock_path = venv.with_extension("lock");
    let lock = std::fs::OpenOptions::new().create(true).truncate(false).write(true).open(&lock_path).map_err(|e| fail(format!("opening {}", lock_path.display()), &e.to_string()))?;
    lock.lock().map_err(|e| fail(format!("locking {}", lock_path.display()), &e.to_string()))?;
    let python = venv.join("bin/python");
    let run_probe = || Command::new(&python).args(["-c", probe]).output();
    if let Ok(out) = run_probe() {
        if out.status.success() {
            return Ok(ToolsVenv { python, probe: String::from_utf8_lossy(&out.stdout).trim().to_string() });
        }
    }
    let out = Command::new("python3").args(["-m", "venv", "--clear"]).arg(venv).output().map_err(|e| fail("python3 -m venv".into(), &e.to_string()))?;
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
