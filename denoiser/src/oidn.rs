//! Intel Open Image Denoise (OIDN 2.x) as a baseline denoiser: its "RT" filter on our noisy HDR
//! radiance with our albedo and normal G-buffers, on OIDN's CPU device.
//!
//! The library is loaded at run time (dlopen) from a folder given by the caller and called
//! through its C API, so building pixguide never needs OIDN; the binary gets the folder from the
//! pyoidn wheel (src/cli/oidn_setup.rs). OIDN then loads its CPU device module from that same
//! folder. Signatures and enum values are those of `include/OpenImageDenoise/oidn.h` of OIDN
//! 2.5 (`oidnSetDeviceInt`, `oidnSetFilterBool`, …: the 2.0 names ending in `1i`/`1b` are gone).

use std::ffi::{c_char, c_int, c_void, CStr};
use std::mem::ManuallyDrop;
use std::path::{Path, PathBuf};

/// The file loaded from the library folder (its soname: any 2.x).
pub const LIBRARY: &str = "libOpenImageDenoise.so.2";

type Device = *mut c_void;
type Filter = *mut c_void;

const DEVICE_TYPE_CPU: c_int = 1;
const FORMAT_FLOAT3: c_int = 3;
const QUALITY_HIGH: c_int = 6;

#[derive(Debug, thiserror::Error)]
pub enum OidnError {
    #[error("{path}: cannot load Open Image Denoise: {message}")]
    Load { path: PathBuf, message: String },
    #[error("{path}: no function {symbol} (not an OIDN 2.x library?): {message}")]
    Symbol { path: PathBuf, symbol: &'static str, message: String },
    #[error("{path}: OIDN version {version}, but version 2.x is needed")]
    Version { path: PathBuf, version: String },
    /// An OIDN call reported an error (`oidnGetDeviceError`).
    #[error("OIDN {stage}: {message} (OIDN error code {code})")]
    Call { stage: &'static str, code: i32, message: String },
    #[error("OIDN input {name}: {got} values, but {width}×{height} pixels × 3 channels need {want}")]
    Size { name: &'static str, got: usize, want: usize, width: usize, height: usize },
    #[error("OIDN input {name}: non-finite value at pixel ({x}, {y})")]
    NonFinite { name: &'static str, x: usize, y: usize },
    #[error("OIDN input: empty image ({width}×{height})")]
    Empty { width: usize, height: usize },
}

/// The C functions used, resolved once.
struct Api {
    new_device: unsafe extern "C" fn(c_int) -> Device,
    set_device_int: unsafe extern "C" fn(Device, *const c_char, c_int),
    get_device_int: unsafe extern "C" fn(Device, *const c_char) -> c_int,
    commit_device: unsafe extern "C" fn(Device),
    release_device: unsafe extern "C" fn(Device),
    get_device_error: unsafe extern "C" fn(Device, *mut *const c_char) -> c_int,
    new_filter: unsafe extern "C" fn(Device, *const c_char) -> Filter,
    set_shared_filter_image: unsafe extern "C" fn(Filter, *const c_char, *mut c_void, c_int, usize, usize, usize, usize, usize),
    set_filter_bool: unsafe extern "C" fn(Filter, *const c_char, bool),
    set_filter_int: unsafe extern "C" fn(Filter, *const c_char, c_int),
    commit_filter: unsafe extern "C" fn(Filter),
    execute_filter: unsafe extern "C" fn(Filter),
    release_filter: unsafe extern "C" fn(Filter),
}

/// A loaded OIDN library with a committed CPU device.
pub struct Oidn {
    api: Api,
    device: Device,
    version: String,
    threads: usize,
    path: PathBuf,
    /// Never unloaded: OIDN's worker threads (TBB) may outlive the device, and unmapping code
    /// they may still run is unsafe.
    _lib: ManuallyDrop<libloading::Library>,
}

impl Oidn {
    /// Loads `lib_dir/libOpenImageDenoise.so.2` and creates a CPU device with `threads` worker
    /// threads (0: OIDN's choice, all cores). The library's own dependencies (its core library,
    /// TBB) are found through its RPATH (`$ORIGIN`), so only the full path is needed.
    pub fn load(lib_dir: &Path, threads: usize) -> Result<Oidn, OidnError> {
        let path = lib_dir.join(LIBRARY);
        // SAFETY: loading runs the library's initialisers; OIDN's have no preconditions.
        let lib = unsafe { libloading::Library::new(&path) }.map_err(|e| OidnError::Load { path: path.clone(), message: e.to_string() })?;
        let api = Api {
            new_device: sym(&lib, &path, "oidnNewDevice")?,
            set_device_int: sym(&lib, &path, "oidnSetDeviceInt")?,
            get_device_int: sym(&lib, &path, "oidnGetDeviceInt")?,
            commit_device: sym(&lib, &path, "oidnCommitDevice")?,
            release_device: sym(&lib, &path, "oidnReleaseDevice")?,
            get_device_error: sym(&lib, &path, "oidnGetDeviceError")?,
            new_filter: sym(&lib, &path, "oidnNewFilter")?,
            set_shared_filter_image: sym(&lib, &path, "oidnSetSharedFilterImage")?,
            set_filter_bool: sym(&lib, &path, "oidnSetFilterBool")?,
            set_filter_int: sym(&lib, &path, "oidnSetFilterInt")?,
            commit_filter: sym(&lib, &path, "oidnCommitFilter")?,
            execute_filter: sym(&lib, &path, "oidnExecuteFilter")?,
            release_filter: sym(&lib, &path, "oidnReleaseFilter")?,
        };
        let lib = ManuallyDrop::new(lib);
        // SAFETY: every call below follows oidn.h: a device handle from oidnNewDevice (checked
        // for null), NUL-terminated parameter names.
        unsafe {
            let device = (api.new_device)(DEVICE_TYPE_CPU);
            if device.is_null() {
                let (code, message) = error(&api, std::ptr::null_mut());
                return Err(OidnError::Call { stage: "creating the CPU device", code, message });
            }
            let mut oidn = Oidn { api, device, version: String::new(), threads, path, _lib: lib };
            if threads > 0 {
                (oidn.api.set_device_int)(device, c"numThreads".as_ptr(), threads.min(c_int::MAX as usize) as c_int);
            }
            (oidn.api.commit_device)(device);
            oidn.check("committing the CPU device")?;
            // "version" is major·10000 + minor·100 + patch.
            let v = (oidn.api.get_device_int)(device, c"version".as_ptr());
            oidn.check("reading the version")?;
            oidn.version = format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100);
            if v / 10000 != 2 {
                return Err(OidnError::Version { path: oidn.path.clone(), version: oidn.version.clone() });
            }
            Ok(oidn)
        }
    }

    /// OIDN's version, e.g. "2.5.1".
    pub fn version(&self) -> &str {
        &self.version
    }

    /// The library file loaded.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Worker threads asked of the device (0: OIDN's default).
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Denoises a `width × height` frame: `colour` linear HDR radiance, `albedo` and `normal`
    /// G-buffers, all interleaved RGB `[H, W, 3]` like `Frame`'s buffers. Returns the denoised
    /// radiance in the same layout. Every call builds and commits a new filter (OIDN's RT filter,
    /// `hdr`, quality high) and executes it once: that pair is the per-frame cost.
    pub fn denoise(&self, colour: &[f32], albedo: &[f32], normal: &[f32], width: usize, height: usize) -> Result<Vec<f32>, OidnError> {
        check_inputs(&[("colour", colour), ("albedo", albedo), ("normal", normal)], width, height)?;
        let mut output = vec![0.0f32; width * height * 3];
        // SAFETY: the filter handle is checked for null and released by the guard; the images
        // are `width × height` FLOAT3 (checked above) and outlive the filter, which only reads
        // the three inputs (the pointers are cast to `*mut` because the C API takes one).
        unsafe {
            let filter = (self.api.new_filter)(self.device, c"RT".as_ptr());
            if filter.is_null() {
                let (code, message) = error(&self.api, self.device);
                return Err(OidnError::Call { stage: "creating the RT filter", code, message });
            }
            let _release = FilterGuard { filter, release: self.api.release_filter };
            let images: [(&CStr, *mut c_void); 4] = [
                (c"color", colour.as_ptr() as *mut c_void),
                (c"albedo", albedo.as_ptr() as *mut c_void),
                (c"normal", normal.as_ptr() as *mut c_void),
                (c"output", output.as_mut_ptr() as *mut c_void),
            ];
            for (name, ptr) in images {
                (self.api.set_shared_filter_image)(filter, name.as_ptr(), ptr, FORMAT_FLOAT3, width, height, 0, 0, 0);
            }
            (self.api.set_filter_bool)(filter, c"hdr".as_ptr(), true);
            (self.api.set_filter_int)(filter, c"quality".as_ptr(), QUALITY_HIGH);
            self.check("setting up the RT filter")?;
            (self.api.commit_filter)(filter);
            self.check("committing the RT filter")?;
            (self.api.execute_filter)(filter);
            self.check("executing the RT filter")?;
        }
        Ok(output)
    }

    /// The device's first pending error, if any, as an `OidnError::Call` of `stage`.
    fn check(&self, stage: &'static str) -> Result<(), OidnError> {
        // SAFETY: `self.device` is a live device handle.
        let (code, message) = unsafe { error(&self.api, self.device) };
        if code == 0 {
            Ok(())
        } else {
            Err(OidnError::Call { stage, code, message })
        }
    }
}

impl Drop for Oidn {
    fn drop(&mut self) {
        // SAFETY: the device was created by this library and is released once.
        unsafe { (self.api.release_device)(self.device) };
    }
}

struct FilterGuard {
    filter: Filter,
    release: unsafe extern "C" fn(Filter),
}

impl Drop for FilterGuard {
    fn drop(&mut self) {
        // SAFETY: the filter was created by oidnNewFilter and is released once.
        unsafe { (self.release)(self.filter) };
    }
}

/// The function `name` of `lib`, as the function pointer type `T`.
fn sym<T: Copy>(lib: &libloading::Library, path: &Path, name: &'static str) -> Result<T, OidnError> {
    // SAFETY: every `T` asked for is the function's C signature in oidn.h (OIDN 2.5); the pointer
    // stays valid because the library is never unloaded.
    unsafe { lib.get::<T>(name.as_bytes()) }.map(|s| *s).map_err(|e| OidnError::Symbol {
        path: path.to_path_buf(),
        symbol: name,
        message: e.to_string(),
    })
}

/// `oidnGetDeviceError` of `device` (null: the error of a failed device creation).
///
/// # Safety
/// `device` is null or a live device of the library `api` came from.
unsafe fn error(api: &Api, device: Device) -> (i32, String) {
    let mut msg: *const c_char = std::ptr::null();
    let code = unsafe { (api.get_device_error)(device, &mut msg) };
    let message = if msg.is_null() { "no message".to_string() } else { unsafe { CStr::from_ptr(msg) }.to_string_lossy().into_owned() };
    (code, message)
}

/// Sizes and finiteness of the inputs: OIDN reads exactly `width × height × 3` floats of each,
/// and a NaN or infinity would spread over the whole neighbourhood it filters.
fn check_inputs(inputs: &[(&'static str, &[f32])], width: usize, height: usize) -> Result<(), OidnError> {
    if width == 0 || height == 0 {
        return Err(OidnError::Empty { width, height });
    }
    let want = width.checked_mul(height).and_then(|n| n.checked_mul(3)).ok_or(OidnError::Empty { width, height })?;
    for &(name, v) in inputs {
        if v.len() != want {
            return Err(OidnError::Size { name, got: v.len(), want, width, height });
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            let p = i / 3;
            return Err(OidnError::NonFinite { name, x: p % width, y: p / width });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_are_checked_before_any_call() {
        let ok = vec![0.5f32; 4 * 3 * 3];
        assert!(check_inputs(&[("colour", &ok), ("albedo", &ok)], 4, 3).is_ok());
        let short = vec![0.5f32; 4 * 3 * 3 - 1];
        let e = check_inputs(&[("colour", &ok), ("albedo", &short)], 4, 3).unwrap_err();
        assert!(matches!(e, OidnError::Size { name: "albedo", got: 35, want: 36, .. }), "{e}");
        let mut nan = ok.clone();
        nan[(2 * 4 + 1) * 3 + 2] = f32::NAN;
        let e = check_inputs(&[("normal", &nan)], 4, 3).unwrap_err();
        assert!(matches!(e, OidnError::NonFinite { name: "normal", x: 1, y: 2 }), "{e}");
        assert!(matches!(check_inputs(&[("colour", &[])], 0, 3), Err(OidnError::Empty { .. })));
    }

    #[test]
    fn a_missing_library_is_a_load_error_naming_the_file() {
        let dir = Path::new("/nonexistent/oidn/lib");
        match Oidn::load(dir, 1) {
            Err(OidnError::Load { path, .. }) => assert_eq!(path, dir.join(LIBRARY)),
            Err(e) => panic!("expected a load error, got {e}"),
            Ok(_) => panic!("loaded a library from a folder that does not exist"),
        }
    }
}
