//! Colour parameters of BSDFs: constants, `bitmap` and `checkerboard` textures (inline or by
//! `<ref>`), with their uv transforms, turned into the material's colours or their means.

use super::Loader;
use crate::scene::{image_io, ColorParam};
use crate::{Error, Result};
use glam::{Affine2, Vec2, Vec3};
use roxmltree::Node;
use std::path::PathBuf;

/// A colour parameter: a constant or a texture node (resolved when the material is built),
/// with the name of the BSDF parameter that holds it (errors name it).
pub(super) enum Spectrum<'a, 'i> {
    Const(Vec3),
    Texture { node: Node<'a, 'i>, param: String },
}

/// A texture as read from the XML, before its image is loaded.
enum TextureDef {
    Bitmap { file: PathBuf, to_uv: Affine2 },
    Checkerboard { color0: Vec3, color1: Vec3, to_uv: Affine2 },
}

impl<'a, 'i> Loader<'a, 'i> {
    /// A colour parameter: constant, an inline texture, or a `<ref>` to a texture.
    pub(super) fn spectrum(&self, n: Node<'a, 'i>) -> Result<Spectrum<'a, 'i>> {
        let param = n.attribute("name").unwrap_or("(unnamed)").to_string();
        match n.tag_name().name() {
            "rgb" | "srgb" | "spectrum" => Ok(Spectrum::Const(self.color(n)?)),
            "float" => Ok(Spectrum::Const(Vec3::splat(self.float(n)?.max(0.0)))),
            "texture" => Ok(Spectrum::Texture { node: n, param }),
            "ref" => {
                let id = self.required(n, "id")?;
                let node = *self.textures.get(&id).ok_or_else(|| self.err(n, format!("no <texture id=\"{id}\"> defined before this")))?;
                Ok(Spectrum::Texture { node, param })
            }
            other => Err(self.err(n, format!("<{other}> is not a colour"))),
        }
    }

    /// Where a texture is in the file and which BSDF parameter uses it, for errors:
    /// `line 79 <texture type="bitmap"> (specularReflectance)`.
    fn texture_field(&self, t: Node<'a, 'i>, param: &str) -> String {
        format!("{} ({param})", self.describe(t))
    }

    /// Reads a `bitmap` or `checkerboard` texture. Texture coordinates are mapped by Mitsuba
    /// 3's `to_uv` transform or Mitsuba 0.6's `uscale`/`vscale`/`uoffset`/`voffset`
    /// (uv · scale + offset).
    fn texture_def(&self, t: Node<'a, 'i>, param: &str) -> Result<TextureDef> {
        let field = self.texture_field(t, param);
        let fail = |n: Node<'a, 'i>, msg: String| {
            let at = if n == t { field.clone() } else { format!("{} in {field}", self.describe(n)) };
            Error::scene(&self.file, at, msg)
        };
        let ty = self.attr(t, "type")?.ok_or_else(|| fail(t, "missing attribute `type`".into()))?;
        if !matches!(ty.as_str(), "bitmap" | "checkerboard") {
            return Err(fail(t, format!("unsupported texture type \"{ty}\" (bitmap, checkerboard)")));
        }
        let (mut scale, mut offset, mut to_uv, mut old_style) = (Vec2::ONE, Vec2::ZERO, None, false);
        let (mut file, mut color0, mut color1) = (None, Vec3::splat(0.4), Vec3::splat(0.2));
        for c in Self::elements(t) {
            let name = c.attribute("name").unwrap_or("");
            match (ty.as_str(), c.tag_name().name(), name) {
                (_, "float", "uscale" | "vscale" | "uoffset" | "voffset") => {
                    let v = self.float(c)?;
                    old_style = true;
                    match name {
                        "uscale" => scale.x = v,
                        "vscale" => scale.y = v,
                        "uoffset" => offset.x = v,
                        _ => offset.y = v,
                    }
                }
                (_, "transform", "to_uv" | "toUV") => {
                    // The 2-D affine part: x and y rows, x and y columns and the translation.
                    let m = self.transform(c)?;
                    to_uv = Some(Affine2::from_cols(
                        m.x_axis.truncate().truncate(),
                        m.y_axis.truncate().truncate(),
                        m.w_axis.truncate().truncate(),
                    ));
                }
                ("bitmap", "string", "filename") => file = Some(self.required(c, "value")?),
                // Filtering: ours is bilinear (no MIP maps).
                ("bitmap", "string", "filterType" | "filter_type")
                | ("bitmap", "float", "maxAnisotropy")
                | ("bitmap", "boolean", "cache") => {}
                ("bitmap", "string", "wrapMode" | "wrapModeU" | "wrapModeV" | "wrap_mode") => {
                    let v = self.required(c, "value")?;
                    if v != "repeat" {
                        self.warn(c, format!("{param}: wrap mode \"{v}\" becomes repeat"));
                    }
                }
                ("bitmap", "float", "gamma") => {
                    let g = self.float(c)?;
                    if g != -1.0 && (g - 2.2).abs() > 1e-3 {
                        return Err(fail(c, format!("gamma {g} is not supported (8-bit images are read as sRGB, float images as linear)")));
                    }
                }
                ("bitmap", "boolean", "raw") => {
                    if self.boolean(c)? {
                        return Err(fail(c, "raw=true is not supported (8-bit images are always read as sRGB)".into()));
                    }
                }
                ("checkerboard", _, "color0" | "color1") => {
                    let v = match c.tag_name().name() {
                        "float" => Vec3::splat(self.float(c)?.max(0.0)),
                        "rgb" | "srgb" | "spectrum" => self.color(c)?,
                        other => return Err(fail(c, format!("{name} must be a constant colour, not <{other}>"))),
                    };
                    if name == "color0" {
                        color0 = v
                    } else {
                        color1 = v
                    }
                }
                _ => return Err(fail(c, format!("unsupported {ty} parameter"))),
            }
        }
        let to_uv = match (to_uv, old_style) {
            (Some(_), true) => return Err(fail(t, "give either to_uv or uscale/vscale/uoffset/voffset, not both".into())),
            (Some(m), false) => m,
            (None, _) => Affine2::from_scale_angle_translation(scale, 0.0, offset),
        };
        if !to_uv.is_finite() {
            return Err(fail(t, "the texture coordinate transform is not finite".into()));
        }
        Ok(match ty.as_str() {
            "bitmap" => {
                let file = file.ok_or_else(|| fail(t, "a bitmap needs <string name=\"filename\">".into()))?;
                TextureDef::Bitmap { file: self.dir.join(file), to_uv }
            }
            _ => TextureDef::Checkerboard { color0, color1, to_uv },
        })
    }

    /// A colour parameter that may vary over the surface (diffuse reflectance, a conductor's
    /// specular reflectance): constants and checkerboards as they are, bitmaps loaded as
    /// textures, all values capped at 1 (a reflectance).
    pub(super) fn color_param(&mut self, s: Spectrum<'a, 'i>) -> Result<ColorParam> {
        match s {
            Spectrum::Const(c) => Ok(ColorParam::Const(c.min(Vec3::ONE))),
            Spectrum::Texture { node, param } => match self.texture_def(node, &param)? {
                TextureDef::Bitmap { file, to_uv } => {
                    let field = self.texture_field(node, &param);
                    let index = self.b.albedo_texture(&file, &field)?;
                    Ok(ColorParam::Texture { index, scale: Vec3::ONE, to_uv })
                }
                TextureDef::Checkerboard { color0, color1, to_uv } => {
                    Ok(ColorParam::Checkerboard { color0: color0.min(Vec3::ONE), color1: color1.min(Vec3::ONE), to_uv })
                }
            },
        }
    }

    /// A constant colour or a texture's mean, for parameters that cannot vary over a surface;
    /// `true` if it was a texture.
    pub(super) fn mean_color(&self, s: Spectrum<'a, 'i>) -> Result<(Vec3, bool)> {
        match s {
            Spectrum::Const(c) => Ok((c, false)),
            Spectrum::Texture { node, param } => {
                let mean = match self.texture_def(node, &param)? {
                    TextureDef::Bitmap { file, .. } => image_io::load_image(&file, &self.file, &self.texture_field(node, &param))?.mean(),
                    TextureDef::Checkerboard { color0, color1, .. } => (color0 + color1) * 0.5,
                };
                Ok((mean, true))
            }
        }
    }
}
