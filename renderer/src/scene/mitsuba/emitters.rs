//! `<emitter>`: the area emitter of a shape and the scene's constant environment.

use super::Loader;
use crate::light::Environment;
use crate::Result;
use glam::Vec3;
use roxmltree::Node;

impl<'a, 'i> Loader<'a, 'i> {
    /// A shape's `<emitter>`: its radiance (only area emitters can sit on a shape).
    pub(super) fn area_emitter(&self, c: Node<'a, 'i>) -> Result<Vec3> {
        let et = self.required(c, "type")?;
        if et != "area" {
            return Err(self.err(c, format!("a shape's emitter must be \"area\", not \"{et}\"")));
        }
        let mut radiance = None;
        for p in Self::elements(c) {
            match p.attribute("name") {
                Some("radiance") => radiance = Some(self.color(p)?),
                Some("samplingWeight" | "sampling_weight") => {}
                _ => return Err(self.err(p, "unsupported area emitter parameter")),
            }
        }
        radiance.ok_or_else(|| self.err(c, "an area emitter needs <rgb name=\"radiance\">"))
    }

    pub(super) fn environment(&self, n: Node<'a, 'i>) -> Result<Environment> {
        let ty = self.required(n, "type")?;
        if ty != "constant" {
            return Err(self.err(n, format!("unsupported emitter type \"{ty}\" (area emitters on shapes and \"constant\" are supported)")));
        }
        let mut radiance = Vec3::ONE;
        for c in Self::elements(n) {
            match c.attribute("name") {
                Some("radiance") => radiance = self.color(c)?,
                Some("samplingWeight" | "sampling_weight") => {}
                _ => return Err(self.err(c, "unsupported constant emitter parameter")),
            }
        }
        Ok(Environment::Constant(radiance))
    }
}
