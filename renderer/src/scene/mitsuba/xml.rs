//! Reading values out of Mitsuba XML elements: where an element is (the `line 12 <bsdf
//! type="hair">` that errors and warnings name), attributes with `$name` defaults substituted,
//! and the typed values of properties (numbers, booleans, colours, points, transforms).

use super::Loader;
use crate::scene::builder::warn;
use crate::texture::srgb_to_linear;
use crate::{Error, Result};
use glam::{Mat4, Vec3};
use roxmltree::Node;

impl<'a, 'i> Loader<'a, 'i> {
    pub(super) fn line(&self, n: Node<'a, 'i>) -> u32 {
        self.doc.text_pos_at(n.range().start).row
    }

    pub(super) fn describe(&self, n: Node<'a, 'i>) -> String {
        match n.attribute("type").or_else(|| n.attribute("name")) {
            Some(t) if n.has_attribute("type") => format!("line {} <{} type=\"{t}\">", self.line(n), n.tag_name().name()),
            Some(t) => format!("line {} <{} name=\"{t}\">", self.line(n), n.tag_name().name()),
            None => format!("line {} <{}>", self.line(n), n.tag_name().name()),
        }
    }

    pub(super) fn err(&self, n: Node<'a, 'i>, message: impl Into<String>) -> Error {
        Error::scene(&self.file, self.describe(n), message)
    }

    pub(super) fn warn(&self, n: Node<'a, 'i>, message: impl std::fmt::Display) {
        warn(&self.file, format!("{}: {message}", self.describe(n)));
    }

    /// An attribute with `$name` defaults substituted.
    pub(super) fn attr(&self, n: Node<'a, 'i>, key: &str) -> Result<Option<String>> {
        let Some(v) = n.attribute(key) else { return Ok(None) };
        if !v.contains('$') {
            return Ok(Some(v.to_string()));
        }
        let mut out = String::new();
        let mut rest = v;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after.find(|c: char| !(c.is_alphanumeric() || c == '_')).unwrap_or(after.len());
            let name = &after[..len];
            let value = self
                .defaults
                .get(name)
                .ok_or_else(|| self.err(n, format!("attribute {key}=\"{v}\" uses ${name}, which has no <default>")))?;
            out.push_str(value);
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(Some(out))
    }

    pub(super) fn required(&self, n: Node<'a, 'i>, key: &str) -> Result<String> {
        self.attr(n, key)?.ok_or_else(|| self.err(n, format!("missing attribute `{key}`")))
    }

    pub(super) fn elements(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
        n.children().filter(|c| c.is_element())
    }

    pub(super) fn float(&self, n: Node<'a, 'i>) -> Result<f32> {
        let v = self.required(n, "value")?;
        let x: f32 = v.trim().parse().map_err(|_| self.err(n, format!("value \"{v}\" is not a number")))?;
        if !x.is_finite() {
            return Err(self.err(n, format!("value \"{v}\" is not finite")));
        }
        Ok(x)
    }

    pub(super) fn integer(&self, n: Node<'a, 'i>) -> Result<i64> {
        let v = self.required(n, "value")?;
        v.trim().parse().map_err(|_| self.err(n, format!("value \"{v}\" is not an integer")))
    }

    pub(super) fn boolean(&self, n: Node<'a, 'i>) -> Result<bool> {
        match self.required(n, "value")?.trim() {
            "true" => Ok(true),
            "false" => Ok(false),
            v => Err(self.err(n, format!("value \"{v}\" is not true or false"))),
        }
    }

    /// Numbers separated by commas and/or whitespace.
    pub(super) fn numbers(&self, n: Node<'a, 'i>, v: &str) -> Result<Vec<f32>> {
        v.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f32>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| self.err(n, format!("\"{s}\" in \"{v}\" is not a finite number")))
            })
            .collect()
    }

    /// `<rgb>`, `<srgb>` or a constant `<spectrum>` (one value, or three for RGB).
    pub(super) fn color(&self, n: Node<'a, 'i>) -> Result<Vec3> {
        let v = self.required(n, "value")?;
        let tag = n.tag_name().name();
        if tag == "spectrum" && v.contains(':') {
            return Err(self.err(n, "sampled spectra (wavelength:value pairs) are not supported; give an <rgb>"));
        }
        let c = if tag == "srgb" && v.trim_start().starts_with('#') {
            let hex = v.trim().trim_start_matches('#');
            let byte = |i: usize| u8::from_str_radix(hex.get(i..i + 2).unwrap_or("zz"), 16).ok();
            match (hex.len(), byte(0), byte(2), byte(4)) {
                (6, Some(r), Some(g), Some(b)) => Vec3::new(r as f32, g as f32, b as f32) / 255.0,
                _ => return Err(self.err(n, format!("\"{v}\" is not a #rrggbb colour"))),
            }
        } else {
            match self.numbers(n, &v)?.as_slice() {
                [x] => Vec3::splat(*x),
                [r, g, b] => Vec3::new(*r, *g, *b),
                _ => return Err(self.err(n, format!("\"{v}\" is neither one value nor three"))),
            }
        };
        let c = if tag == "srgb" { Vec3::new(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z)) } else { c };
        if c.min_element() < 0.0 {
            return Err(self.err(n, format!("colour {c} has a negative component")));
        }
        Ok(c)
    }

    /// `<point>`/`<vector>`: x, y, z attributes (missing = 0) or a `value` list.
    pub(super) fn point(&self, n: Node<'a, 'i>) -> Result<Vec3> {
        if let Some(v) = self.attr(n, "value")? {
            return match self.numbers(n, &v)?.as_slice() {
                [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                _ => Err(self.err(n, format!("\"{v}\" is not three numbers"))),
            };
        }
        let mut p = Vec3::ZERO;
        for (i, k) in ["x", "y", "z"].iter().enumerate() {
            if let Some(v) = self.attr(n, k)? {
                p[i] = self.numbers(n, &v)?.first().copied().ok_or_else(|| self.err(n, format!("{k} is empty")))?;
            }
        }
        Ok(p)
    }

    /// A `<transform>`: its operations in document order, each applied after the previous ones.
    pub(super) fn transform(&self, n: Node<'a, 'i>) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for op in Self::elements(n) {
            let xyz = |default: f32| -> Result<Vec3> {
                let mut v = Vec3::splat(default);
                if let Some(s) = self.attr(op, "value")? {
                    let nums = self.numbers(op, &s)?;
                    return match nums.as_slice() {
                        [x] => Ok(Vec3::splat(*x)),
                        [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                        _ => Err(self.err(op, format!("\"{s}\" is neither one value nor three"))),
                    };
                }
                for (i, k) in ["x", "y", "z"].iter().enumerate() {
                    if let Some(s) = self.attr(op, k)? {
                        v[i] = s
                            .trim()
                            .parse::<f32>()
                            .ok()
                            .filter(|x| x.is_finite())
                            .ok_or_else(|| self.err(op, format!("{k}=\"{s}\" is not a number")))?;
                    }
                }
                Ok(v)
            };
            let step = match op.tag_name().name() {
                "matrix" => {
                    let v = self.required(op, "value")?;
                    let a = self.numbers(op, &v)?;
                    if a.len() != 16 {
                        return Err(self.err(op, format!("a matrix needs 16 numbers, got {}", a.len())));
                    }
                    if a[12..] != [0.0, 0.0, 0.0, 1.0] {
                        return Err(self.err(op, "the last row must be 0 0 0 1 (projective transforms are not supported)"));
                    }
                    // Row-major in the file; glam is column-major.
                    Mat4::from_cols_array(&a.try_into().unwrap()).transpose()
                }
                "translate" => Mat4::from_translation(xyz(0.0)?),
                "scale" => Mat4::from_scale(xyz(1.0)?),
                "rotate" => {
                    let axis = xyz(0.0)?;
                    let angle = self.attr(op, "angle")?.ok_or_else(|| self.err(op, "missing attribute `angle`"))?;
                    let angle: f32 = angle
                        .trim()
                        .parse()
                        .ok()
                        .filter(|a: &f32| a.is_finite())
                        .ok_or_else(|| self.err(op, format!("angle \"{angle}\" is not a number")))?;
                    let axis = axis.try_normalize().ok_or_else(|| self.err(op, "the rotation axis is zero"))?;
                    Mat4::from_axis_angle(axis, angle.to_radians())
                }
                "lookat" | "lookAt" => {
                    let vec = |k: &str| -> Result<Vec3> {
                        let s = self.attr(op, k)?.ok_or_else(|| self.err(op, format!("missing attribute `{k}`")))?;
                        match self.numbers(op, &s)?.as_slice() {
                            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                            _ => Err(self.err(op, format!("{k}=\"{s}\" is not three numbers"))),
                        }
                    };
                    let (origin, target) = (vec("origin")?, vec("target")?);
                    let up = if op.has_attribute("up") { vec("up")? } else { Vec3::Y };
                    let dir = (target - origin).try_normalize().ok_or_else(|| self.err(op, "origin equals target"))?;
                    let left = up.cross(dir).try_normalize().ok_or_else(|| self.err(op, "up is zero or parallel to the view"))?;
                    let new_up = dir.cross(left);
                    Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0))
                }
                other => return Err(self.err(op, format!("unsupported transform operation <{other}>"))),
            };
            m = step * m;
        }
        if !m.is_finite() {
            return Err(self.err(n, "the transform is not finite"));
        }
        Ok(m)
    }
}
