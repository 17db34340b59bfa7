//! Mitsuba 0.5/0.6 XML scenes: the subset of the format that the scenes of Bitterli's
//! rendering resources (the collection the paper trained on) use. docs/scene-format.md,
//! "Mitsuba XML", lists what is read and how it is approximated.
//!
//! Everything the loader does not understand is an error naming the file, the line and the
//! element (`scene.xml: line 12 <bsdf type="hair">: unsupported BSDF type`), never a silent
//! default: a scene that renders differently from what its author made would poison a test.
//! The few things that are read but approximated (a textured dielectric or plastic specular
//! reflectance becomes its mean, anisotropic roughness becomes isotropic) print a warning.
//! renderer/tests/mitsuba_crosscheck.rs renders scenes in both renderers and compares them.
//! Texture lookups (`bitmap`, `checkerboard`) follow Mitsuba 3, which agrees with 0.6 on uv ≥ 0.
//!
//! The loader is one `Loader` whose methods are spread over the submodules by what they read:
//! `xml` (element positions, attributes, typed values), `sensor` (camera and integrator),
//! `textures`, `bsdfs`, `shapes` and `emitters`; this file holds the entry point, the loader's
//! state and the walk over `<scene>`'s children.

mod bsdfs;
mod emitters;
mod sensor;
mod shapes;
mod textures;
mod xml;

use super::builder::{warn, Builder};
use super::{MaterialKind, RenderSettings, SceneDescription};
use crate::light::Environment;
use crate::{Error, Result};
use glam::Vec3;
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Mitsuba's default film size (768 × 576).
const DEFAULT_FILM: (u32, u32) = (768, 576);

/// Loads a Mitsuba XML scene.
pub fn load(path: &Path) -> Result<SceneDescription> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let doc = Document::parse(&text).map_err(|e| {
        let p = e.pos();
        Error::scene(path, format!("line {}, column {}", p.row, p.col), format!("malformed XML: {e}"))
    })?;
    let root = doc.root_element();
    let mut l = Loader {
        file: path.to_path_buf(),
        dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
        doc: &doc,
        defaults: HashMap::new(),
        bsdfs: HashMap::new(),
        textures: HashMap::new(),
        b: Builder::new(path),
    };
    if root.tag_name().name() != "scene" {
        return Err(l.err(root, "the root element must be <scene>"));
    }
    l.run(root)
}

/// A BSDF read from the XML, before it becomes a scene material (emitters copy it).
#[derive(Clone)]
struct BsdfDef {
    name: String,
    kind: MaterialKind,
    /// Wrapped in `twosided`: shaded alike from both sides (else black from behind).
    two_sided: bool,
}

struct Loader<'a, 'i> {
    file: PathBuf,
    dir: PathBuf,
    doc: &'a Document<'i>,
    /// `<default name value>` parameters, substituted for `$name` in attribute values.
    defaults: HashMap<String, String>,
    bsdfs: HashMap<String, BsdfDef>,
    textures: HashMap<String, Node<'a, 'i>>,
    b: Builder,
}

impl<'a, 'i> Loader<'a, 'i> {
    fn run(&mut self, root: Node<'a, 'i>) -> Result<SceneDescription> {
        let mut settings = RenderSettings::default();
        let mut camera_node = None;
        let mut environment = Environment::Constant(Vec3::ZERO);
        for n in Self::elements(root) {
            match n.tag_name().name() {
                "default" => {
                    let name = self.required(n, "name")?;
                    let value = self.required(n, "value")?;
                    self.defaults.entry(name).or_insert(value);
                }
                "integrator" => self.integrator(n, &mut settings)?,
                "sensor" => {
                    if camera_node.is_some() {
                        return Err(self.err(n, "a second <sensor> (only one camera is supported)"));
                    }
                    camera_node = Some(n);
                }
                "bsdf" => {
                    let id = self.attr(n, "id")?.ok_or_else(|| self.err(n, "a top-level <bsdf> needs an id"))?;
                    let def = self.bsdf(n, &id)?;
                    self.bsdfs.insert(id, def);
                }
                "texture" => {
                    let id = self.attr(n, "id")?.ok_or_else(|| self.err(n, "a top-level <texture> needs an id"))?;
                    self.textures.insert(id, n);
                }
                "shape" => self.shape(n)?,
                "emitter" => environment = self.environment(n)?,
                other => return Err(self.err(n, format!("unsupported element <{other}> in <scene>"))),
            }
        }
        let camera = match camera_node {
            Some(n) => self.sensor(n, &mut settings)?,
            None => {
                warn(&self.file, "no <sensor>; using a camera that frames the scene bounds");
                self.b.framing_camera(DEFAULT_FILM.0, DEFAULT_FILM.1)?
            }
        };
        let b = std::mem::replace(&mut self.b, Builder::new(&self.file));
        b.finish(camera, settings, environment)
    }
}
