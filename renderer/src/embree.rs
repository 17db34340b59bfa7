//! Embree 4, loaded at run time (dlopen) and called through its C API in this process: the
//! ray benchmark's fairest peer. Through the embreex Python binding (`bench::embree_trace`)
//! Embree runs in another process, a second or more apart from our runs, and its per-ray figure
//! includes the binding's loop and its ten output arrays (7–10 % of Embree's time,
//! docs/performance.md); here both BVHs trace the same rays from the same memory in one loop
//! each, alternating, on the same thread.
//!
//! Building pixguide never needs Embree: the library is the one the embreex wheel ships
//! (`embreex.libs/libembree4-*.so.4`, with its TBB beside it, found through its `$ORIGIN`
//! RPATH). Signatures, struct layouts and enum values are those of Embree 4's
//! `include/embree4/rtcore_*.h`.

use crate::geometry::Mesh;
use glam::Vec3;
use std::ffi::{c_char, c_uint, c_void};
use std::mem::ManuallyDrop;
use std::path::{Path, PathBuf};

type Device = *mut c_void;
type Scene = *mut c_void;
type Geometry = *mut c_void;

const GEOMETRY_TYPE_TRIANGLE: c_uint = 0;
const BUFFER_TYPE_INDEX: c_uint = 0;
const BUFFER_TYPE_VERTEX: c_uint = 1;
const FORMAT_UINT3: c_uint = 0x5003;
const FORMAT_FLOAT3: c_uint = 0x9003;
/// `RTC_SCENE_FLAG_ROBUST`: watertight traversal and intersection (slower).
const SCENE_FLAG_ROBUST: c_uint = 1 << 2;
const INVALID_GEOMETRY_ID: u32 = u32::MAX;

#[derive(Debug, thiserror::Error)]
pub enum EmbreeError {
    #[error("{path}: cannot load Embree: {message}")]
    Load { path: PathBuf, message: String },
    #[error("{path}: no function {symbol} (not an Embree 4 library?): {message}")]
    Symbol { path: PathBuf, symbol: &'static str, message: String },
    #[error("{0}: no libembree4*.so* (is embreex installed in this venv?)")]
    NotFound(PathBuf),
    /// An Embree call failed (`rtcGetDeviceError`'s code, or a null handle).
    #[error("Embree {stage} failed (RTCError {code})")]
    Call { stage: &'static str, code: i32 },
    #[error("Embree scene: {0} triangles, more than 32-bit vertex indices hold at three vertices each")]
    TooLarge(usize),
}

/// `struct RTCRayHit` (16-byte aligned; `RTCRay` is 48 bytes, `RTCHit` follows it). The tail
/// leaves room for `instID` and, in builds with instance arrays, `instPrimID`
/// (`RTC_MAX_INSTANCE_LEVEL_COUNT` entries each, 1 by default), which Embree writes.
#[repr(C, align(16))]
struct RayHit {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst: [u32; 9],
}

/// `struct RTCRayHit16`: `RTCRay16` (12 arrays of 16) then `RTCHit16` (7 arrays of 16, then
/// `instID` and, in builds with instance arrays, `instPrimID`; room for four levels here).
#[repr(C, align(64))]
struct RayHit16 {
    org: [[f32; 16]; 3],
    tnear: [f32; 16],
    dir: [[f32; 16]; 3],
    time: [f32; 16],
    tfar: [f32; 16],
    mask: [u32; 16],
    id: [u32; 16],
    flags: [u32; 16],
    ng: [[f32; 16]; 3],
    u: [f32; 16],
    v: [f32; 16],
    prim_id: [u32; 16],
    geom_id: [u32; 16],
    inst: [[u32; 16]; 4],
}

#[repr(C, align(64))]
struct Valid16([i32; 16]);

/// The C functions used, resolved once.
struct Api {
    new_device: unsafe extern "C" fn(*const c_char) -> Device,
    release_device: unsafe extern "C" fn(Device),
    get_device_error: unsafe extern "C" fn(Device) -> i32,
    new_scene: unsafe extern "C" fn(Device) -> Scene,
    set_scene_flags: unsafe extern "C" fn(Scene, c_uint),
    commit_scene: unsafe extern "C" fn(Scene),
    release_scene: unsafe extern "C" fn(Scene),
    new_geometry: unsafe extern "C" fn(Device, c_uint) -> Geometry,
    set_new_geometry_buffer: unsafe extern "C" fn(Geometry, c_uint, c_uint, c_uint, usize, usize) -> *mut c_void,
    commit_geometry: unsafe extern "C" fn(Geometry),
    attach_geometry: unsafe extern "C" fn(Scene, Geometry) -> c_uint,
    release_geometry: unsafe extern "C" fn(Geometry),
    intersect1: unsafe extern "C" fn(Scene, *mut RayHit, *mut c_void),
    intersect16: unsafe extern "C" fn(*const Valid16, Scene, *mut RayHit16, *mut c_void),
}

/// A loaded Embree 4 library with a device of its default configuration (as embreex makes).
pub struct Embree {
    api: Api,
    device: Device,
    path: PathBuf,
    /// Never unloaded: Embree's TBB worker threads outlive the device.
    _lib: ManuallyDrop<libloading::Library>,
}

// SAFETY: an Embree device may be used from any thread (rtcore is thread-safe for scene
// creation and queries on committed scenes); `Embree` only hands out `&self` methods.
unsafe impl Send for Embree {}
unsafe impl Sync for Embree {}

/// The Embree library inside an embreex venv (`venv/lib/python3.*/site-packages/embreex.libs/`).
pub fn library_in_venv(venv: &Path) -> Result<PathBuf, EmbreeError> {
    let not_found = || EmbreeError::NotFound(venv.to_path_buf());
    let lib = venv.join("lib");
    let mut found = Vec::new();
    for py in std::fs::read_dir(&lib).map_err(|_| not_found())?.flatten() {
        let libs = py.path().join("site-packages/embreex.libs");
        for f in std::fs::read_dir(&libs).into_iter().flatten().flatten() {
            let name = f.file_name().to_string_lossy().into_owned();
            if name.starts_with("libembree4") && name.contains(".so") {
                found.push(f.path());
            }
        }
    }
    found.sort();
    found.pop().ok_or_else(not_found)
}

fn sym<T: Copy>(lib: &libloading::Library, path: &Path, name: &'static str) -> Result<T, EmbreeError> {
    // SAFETY: the caller gives `T` the C signature of `name` in Embree 4's headers; the
    // pointer stays valid because the library is never unloaded.
    unsafe { lib.get::<T>(name.as_bytes()) }.map(|s| *s).map_err(|e| EmbreeError::Symbol {
        path: path.to_path_buf(),
        symbol: name,
        message: e.to_string(),
    })
}

impl Embree {
    /// Loads the library at `path` and creates a device (`rtcNewDevice(NULL)`).
    pub fn load(path: &Path) -> Result<Embree, EmbreeError> {
        Embree::load_with_config(path, None)
    }

    /// `load` with an Embree device configuration string (`rtcNewDevice`'s, e.g. `isa=avx2` to
    /// keep Embree to its AVX2 kernels on a CPU that has AVX-512).
    pub fn load_with_config(path: &Path, config: Option<&str>) -> Result<Embree, EmbreeError> {
        let config = config
            .map(|c| std::ffi::CString::new(c).map_err(|_| EmbreeError::Call { stage: "rtcNewDevice (configuration has a NUL)", code: -1 }))
            .transpose()?;
        // SAFETY: loading runs the library's initialisers (Embree's and TBB's), which have no
        // preconditions.
        let lib = unsafe { libloading::Library::new(path) }
            .map_err(|e| EmbreeError::Load { path: path.to_path_buf(), message: e.to_string() })?;
        let api = Api {
            new_device: sym(&lib, path, "rtcNewDevice")?,
            release_device: sym(&lib, path, "rtcReleaseDevice")?,
            get_device_error: sym(&lib, path, "rtcGetDeviceError")?,
            new_scene: sym(&lib, path, "rtcNewScene")?,
            set_scene_flags: sym(&lib, path, "rtcSetSceneFlags")?,
            commit_scene: sym(&lib, path, "rtcCommitScene")?,
            release_scene: sym(&lib, path, "rtcReleaseScene")?,
            new_geometry: sym(&lib, path, "rtcNewGeometry")?,
            set_new_geometry_buffer: sym(&lib, path, "rtcSetNewGeometryBuffer")?,
            commit_geometry: sym(&lib, path, "rtcCommitGeometry")?,
            attach_geometry: sym(&lib, path, "rtcAttachGeometry")?,
            release_geometry: sym(&lib, path, "rtcReleaseGeometry")?,
            intersect1: sym(&lib, path, "rtcIntersect1")?,
            intersect16: sym(&lib, path, "rtcIntersect16")?,
        };
        // SAFETY: a null configuration string is Embree's default configuration; otherwise a
        // NUL-terminated string that lives across the call.
        let device = unsafe { (api.new_device)(config.as_ref().map_or(std::ptr::null(), |c| c.as_ptr())) };
        let embree = Embree { api, device, path: path.to_path_buf(), _lib: ManuallyDrop::new(lib) };
        if device.is_null() {
            return Err(EmbreeError::Call { stage: "rtcNewDevice", code: -1 });
        }
        Ok(embree)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn check(&self, stage: &'static str) -> Result<(), EmbreeError> {
        // SAFETY: `device` is the live device of this library.
        match unsafe { (self.api.get_device_error)(self.device) } {
            0 => Ok(()),
            code => Err(EmbreeError::Call { stage, code }),
        }
    }

    /// A committed scene of `mesh`'s triangles (primitive ids = indices into
    /// `mesh.triangles`), default build quality; `robust` sets `RTC_SCENE_FLAG_ROBUST`. Every
    /// triangle gets three vertices of its own, as embreex's `TriangleMesh` gives Embree the
    /// helper's triangles, so both build from the same input. Non-finite vertices become the
    /// origin, as in the helper (Embree rejects them; our BVH never hits such triangles).
    pub fn scene(&self, mesh: &Mesh, robust: bool) -> Result<EmbreeScene<'_>, EmbreeError> {
        let nt = mesh.triangles.len();
        if nt > (u32::MAX / 3) as usize {
            return Err(EmbreeError::TooLarge(nt));
        }
        // SAFETY: calls follow rtcore's contracts: handles checked for null, buffers filled
        // within the item counts Embree allocated them for (12 bytes an item, as the strides
        // say), the geometry released after it is attached (the scene holds a reference).
        unsafe {
            let scene = (self.api.new_scene)(self.device);
            if scene.is_null() {
                self.check("rtcNewScene")?;
                return Err(EmbreeError::Call { stage: "rtcNewScene", code: -1 });
            }
            let scene = EmbreeScene { embree: self, scene };
            if robust {
                (self.api.set_scene_flags)(scene.scene, SCENE_FLAG_ROBUST);
            }
            let geom = (self.api.new_geometry)(self.device, GEOMETRY_TYPE_TRIANGLE);
            if geom.is_null() {
                self.check("rtcNewGeometry")?;
                return Err(EmbreeError::Call { stage: "rtcNewGeometry", code: -1 });
            }
            let v = (self.api.set_new_geometry_buffer)(geom, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3, 12, 3 * nt) as *mut [f32; 3];
            let i = (self.api.set_new_geometry_buffer)(geom, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3, 12, nt) as *mut [u32; 3];
            if v.is_null() || i.is_null() {
                (self.api.release_geometry)(geom);
                self.check("rtcSetNewGeometryBuffer")?;
                return Err(EmbreeError::Call { stage: "rtcSetNewGeometryBuffer", code: -1 });
            }
            for k in 0..nt {
                for (j, p) in mesh.triangle(k).into_iter().enumerate() {
                    let p = if p.is_finite() { p } else { Vec3::ZERO };
                    v.add(3 * k + j).write(p.to_array());
                }
                let base = 3 * k as u32;
                i.add(k).write([base, base + 1, base + 2]);
            }
            (self.api.commit_geometry)(geom);
            (self.api.attach_geometry)(scene.scene, geom);
            (self.api.release_geometry)(geom);
            self.check("building the geometry")?;
            (self.api.commit_scene)(scene.scene);
            self.check("rtcCommitScene")?;
            Ok(scene)
        }
    }
}

impl Drop for Embree {
    fn drop(&mut self) {
        // SAFETY: every scene borrows `self`, so none outlives the device.
        unsafe { (self.api.release_device)(self.device) };
    }
}

/// A committed Embree scene.
pub struct EmbreeScene<'a> {
    embree: &'a Embree,
    scene: Scene,
}

// SAFETY: a committed Embree scene may be queried from any number of threads at once
// (rtcIntersect1 does not modify it), and it is released only by its owner's drop.
unsafe impl Send for EmbreeScene<'_> {}
unsafe impl Sync for EmbreeScene<'_> {}

impl EmbreeScene<'_> {
    /// Closest hit with t in [0, tmax] (`rtcIntersect1`): primitive id and t.
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<(u32, f32)> {
        let mut rh = RayHit {
            org: o.to_array(),
            tnear: 0.0,
            dir: d.to_array(),
            time: 0.0,
            // Embree wants a finite tfar for a segment; 1e37 is its "unbounded" idiom too.
            tfar: tmax.min(1e37),
            mask: u32::MAX,
            id: 0,
            flags: 0,
            ng: [0.0; 3],
            u: 0.0,
            v: 0.0,
            prim_id: INVALID_GEOMETRY_ID,
            geom_id: INVALID_GEOMETRY_ID,
            inst: [INVALID_GEOMETRY_ID; 9],
        };
        // SAFETY: a committed scene and a ray-hit of `RTCRayHit`'s layout (and more room);
        // null arguments are rtcIntersect1's defaults.
        unsafe { (self.embree.api.intersect1)(self.scene, &mut rh, std::ptr::null_mut()) };
        (rh.geom_id != INVALID_GEOMETRY_ID).then_some((rh.prim_id, rh.tfar))
    }

    /// Closest hits of up to 16 rays (origins, directions, tmax: as `RayBatch` holds them) in one
    /// `rtcIntersect16` call (a packet, as Mitsuba's `llvm_ad_rgb` traces on a CPU with AVX-512),
    /// into `out[..org.len()]`.
    pub fn intersect16(&self, org: &[Vec3], dir: &[Vec3], tmax: &[f32], out: &mut [Option<(u32, f32)>]) {
        let n = org.len();
        assert!(n <= 16 && dir.len() == n && tmax.len() == n && out.len() >= n);
        let mut valid = Valid16([0; 16]);
        // SAFETY: all-zero is a valid bit pattern for every field (plain numbers).
        let mut rh: RayHit16 = unsafe { std::mem::zeroed() };
        for i in 0..n {
            valid.0[i] = -1;
            for a in 0..3 {
                rh.org[a][i] = org[i][a];
                rh.dir[a][i] = dir[i][a];
            }
            rh.tfar[i] = tmax[i].min(1e37);
            rh.mask[i] = u32::MAX;
            rh.prim_id[i] = INVALID_GEOMETRY_ID;
            rh.geom_id[i] = INVALID_GEOMETRY_ID;
        }
        // SAFETY: a committed scene, a 64-byte aligned valid mask and ray-hit packet of
        // `RTCRayHit16`'s layout (and more room); null arguments are the defaults.
        unsafe { (self.embree.api.intersect16)(&valid, self.scene, &mut rh, std::ptr::null_mut()) };
        for (i, o) in out[..n].iter_mut().enumerate() {
            *o = (rh.geom_id[i] != INVALID_GEOMETRY_ID).then_some((rh.prim_id[i], rh.tfar[i]));
        }
    }
}

impl Drop for EmbreeScene<'_> {
    fn drop(&mut self) {
        // SAFETY: the scene was created by this device and is released once.
        unsafe { (self.embree.api.release_scene)(self.scene) };
    }
}
