//! `<sensor>` and `<integrator>`: the camera (a perspective pinhole, its film size and sample
//! count) and the render settings Mitsuba's path tracer parameters map to.

use super::{Loader, DEFAULT_FILM};
use crate::camera::{Camera, FovAxis};
use crate::scene::builder::check_resolution;
use crate::scene::RenderSettings;
use crate::Result;
use glam::{Mat4, Vec3};
use roxmltree::Node;

impl<'a, 'i> Loader<'a, 'i> {
    pub(super) fn integrator(&self, n: Node<'a, 'i>, settings: &mut RenderSettings) -> Result<()> {
        let t = self.required(n, "type")?;
        if !matches!(t.as_str(), "path" | "volpath" | "volpath_simple") {
            return Err(self.err(n, format!("unsupported integrator \"{t}\" (path tracers only)")));
        }
        for c in Self::elements(n) {
            if matches!(c.attribute("name"), Some("maxDepth" | "max_depth")) {
                // Mitsuba's maxDepth counts path segments (2 = direct light only, one scattering
                // event); −1 means unlimited, for which our default stands.
                let d = self.integer(c)?;
                if d >= 1 {
                    settings.max_bounces = (d - 1).min(64) as u32;
                }
            }
            // Other integrator parameters (rrDepth, strictNormals, hideEmitters, ...) tune the
            // sampling of Mitsuba's integrator, not the scene; ours has its own settings.
        }
        Ok(())
    }

    pub(super) fn sensor(&self, n: Node<'a, 'i>, settings: &mut RenderSettings) -> Result<Camera> {
        let t = self.required(n, "type")?;
        if t != "perspective" {
            return Err(self.err(n, format!("unsupported sensor type \"{t}\" (only perspective)")));
        }
        let (mut fov, mut axis, mut to_world) = (None, FovAxis::X, Mat4::IDENTITY);
        let (mut w, mut h) = DEFAULT_FILM;
        for c in Self::elements(n) {
            let name = c.attribute("name").unwrap_or("");
            match (c.tag_name().name(), name) {
                ("float", "fov") => fov = Some(self.float(c)?),
                ("string", "fovAxis" | "fov_axis") => {
                    let v = self.required(c, "value")?;
                    axis = FovAxis::parse(&v)
                        .ok_or_else(|| self.err(c, format!("unknown fov axis \"{v}\" (x, y, diagonal, smaller, larger)")))?;
                }
                ("transform", "toWorld" | "to_world") => to_world = self.transform(c)?,
                // Clip planes and focus distance change nothing for a pinhole camera without clipping.
                (
                    "float",
                    "nearClip" | "farClip" | "focusDistance" | "shutterOpen" | "shutterClose" | "near_clip" | "far_clip" | "focus_distance"
                    | "shutter_open" | "shutter_close",
                ) => {}
                ("sampler", _) => {
                    for s in Self::elements(c) {
                        if matches!(s.attribute("name"), Some("sampleCount" | "sample_count")) {
                            let spp = self.integer(s)?;
                            if spp < 1 || spp > u32::MAX as i64 {
                                return Err(self.err(s, format!("sampleCount {spp} must be at least 1")));
                            }
                            settings.spp = spp as u32;
                        }
                    }
                }
                ("film", _) => {
                    for s in Self::elements(c) {
                        match (s.tag_name().name(), s.attribute("name").unwrap_or("")) {
                            ("integer", "width") => w = self.dim(s)?,
                            ("integer", "height") => h = self.dim(s)?,
                            (
                                "integer",
                                "cropOffsetX" | "cropOffsetY" | "cropWidth" | "cropHeight" | "crop_offset_x" | "crop_offset_y"
                                | "crop_width" | "crop_height",
                            ) => {
                                return Err(self.err(s, "film crop windows are not supported"));
                            }
                            // Output format, tone mapping and the reconstruction filter: how
                            // Mitsuba stores the image, not what the scene looks like.
                            _ => {}
                        }
                    }
                }
                _ => return Err(self.err(c, "unsupported sensor parameter")),
            }
        }
        check_resolution(&self.file, &self.describe(n), w, h)?;
        let fov = fov.ok_or_else(|| self.err(n, "missing <float name=\"fov\"> (focalLength is not supported)"))?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(self.err(n, format!("fov {fov} is outside (0, 180) degrees")));
        }
        // Mitsuba cameras look along +Z with +Y up; +X is the image's left.
        let position = to_world.transform_point3(Vec3::ZERO);
        let forward = to_world.transform_vector3(Vec3::Z).normalize_or_zero();
        let up = to_world.transform_vector3(Vec3::Y).normalize_or_zero();
        let left = to_world.transform_vector3(Vec3::X);
        if left.dot(up.cross(forward)) < 0.0 {
            self.warn(n, "the camera transform mirrors the image; rendering it unmirrored");
        }
        // The camera keeps the axis, so that a new image size (`--size`) keeps the angle along
        // it, as Mitsuba does when the film alone changes.
        Camera::look_at_axis(position, position + forward, up, fov, axis, w, h)
            .ok_or_else(|| self.err(n, "degenerate camera transform (zero or parallel view and up)"))
    }

    fn dim(&self, n: Node<'a, 'i>) -> Result<u32> {
        let v = self.integer(n)?;
        u32::try_from(v).map_err(|_| self.err(n, format!("{v} is not a valid image size")))
    }
}
