//! The one place that names EXR channels; the writer and the reader both use it so they can't
//! disagree. Beauty is plain `R,G,B` so any viewer opens it; auxiliary layers use pbrt-style
//! `Layer.Channel` names (documented in docs/formats.md).

/// A per-pixel buffer's layer: channel names of its mean and of its variance.
pub struct Layer {
    pub mean: &'static [&'static str],
    pub var: &'static [&'static str],
}

pub const RADIANCE: Layer = Layer { mean: &["R", "G", "B"], var: &["Variance.R", "Variance.G", "Variance.B"] };
pub const DIFFUSE: Layer =
    Layer { mean: &["Diffuse.R", "Diffuse.G", "Diffuse.B"], var: &["DiffuseVariance.R", "DiffuseVariance.G", "DiffuseVariance.B"] };
pub const SPECULAR: Layer =
    Layer { mean: &["Specular.R", "Specular.G", "Specular.B"], var: &["SpecularVariance.R", "SpecularVariance.G", "SpecularVariance.B"] };
pub const ALBEDO: Layer =
    Layer { mean: &["Albedo.R", "Albedo.G", "Albedo.B"], var: &["AlbedoVariance.R", "AlbedoVariance.G", "AlbedoVariance.B"] };
pub const NORMAL: Layer = Layer { mean: &["Ns.X", "Ns.Y", "Ns.Z"], var: &["NsVariance.X", "NsVariance.Y", "NsVariance.Z"] };
pub const DEPTH: Layer = Layer { mean: &["Depth.Z"], var: &["DepthVariance.Z"] };

/// Frame metadata: one text header attribute `pixguide` holding `spp=<n> depthScale=<x>`.
pub const ATTR_META: &str = "pixguide";
pub const ATTR_SPP: &str = "spp";
pub const ATTR_DEPTH_SCALE: &str = "depthScale";
