//! The compared methods (method.md §5, §6) as one model type, so that training, weight files,
//! inference and evaluation handle every method the same way.
//!
//! [`MethodModel`] holds per branch only the networks its method uses (the others are `None`),
//! so a weight file contains exactly those tensors, named by module path
//! (`diffuse.d_g.net.layers.0.weight`, …).

use std::time::Instant;

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::column::Column;
use crate::ensemble::{Blend, EnsembleNet};
use crate::kpcn::channels::G_ALBEDO;
use crate::kpcn::{recombine, Variant};
use crate::model::BranchInput;
use crate::model::DenoiserConfig;
use crate::pathnet::{PathNet, PathOutput};
use crate::preprocess::InputTensors;

/// Which auxiliary features a model uses and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// KPCN on G-buffers (D_G).
    G,
    /// KPCN on P-buffers from the path-manifold module (D_P).
    P,
    /// KPCN on G- and P-buffers concatenated (the "both buffers" baseline).
    Both,
    /// D_G and D_P blended per pixel by the ensembling network E (the paper's method).
    Guided,
}

impl Method {
    pub const ALL: [Method; 4] = [Method::G, Method::P, Method::Both, Method::Guided];

    pub fn name(self) -> &'static str {
        match self {
            Method::G => "g",
            Method::P => "p",
            Method::Both => "both",
            Method::Guided => "guided",
        }
    }

    pub fn parse(s: &str) -> Option<Method> {
        s.parse().ok()
    }

    /// Whether the renderer must record per-sample path descriptors for this model.
    pub fn needs_descriptors(self) -> bool {
        self != Method::G
    }
}

crate::names::named!(Method, "method");

/// The ablations of Seed Table 2 (for the guided method): how a guided model was trained, and
/// so part of its weight file's name (`weights::file_stem`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Ablation {
    /// Everything from scratch, jointly.
    FullNFull,
    /// Pretrained D_G, D_P and PathNets frozen; only E trains.
    FixNTrain,
    /// E sees only sg(I_G), sg(I_P).
    RadianceOnly,
}

impl Ablation {
    pub const ALL: [Ablation; 3] = [Ablation::FullNFull, Ablation::FixNTrain, Ablation::RadianceOnly];

    pub fn name(self) -> &'static str {
        match self {
            Ablation::FullNFull => "full-n-full",
            Ablation::FixNTrain => "fix-n-train",
            Ablation::RadianceOnly => "radiance-only",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        s.parse().ok()
    }
}

crate::names::named!(Ablation, "ablation");

/// The networks of one branch (diffuse or specular); unused ones are `None`.
#[derive(Module, Debug)]
pub struct BranchNets {
    pub d_g: Option<Column>,
    pub d_p: Option<Column>,
    pub d_gp: Option<Column>,
    pub path: Option<PathNet>,
    pub e: Option<EnsembleNet>,
}

/// What one branch computed, in its transformed domain, at the output size.
#[derive(Clone, Debug)]
pub struct BranchResult {
    /// The branch's final image (I_E for the guided method).
    pub output: Tensor<4>,
    pub i_g: Option<Tensor<4>>,
    pub i_p: Option<Tensor<4>>,
    /// (W_G, W_P) `[B, 2, h, w]`, guided only.
    pub weights: Option<Tensor<4>>,
    pub path: Option<PathOutput>,
}

/// Both branches and their recombination.
#[derive(Clone, Debug)]
pub struct MethodOutput {
    pub diffuse: BranchResult,
    pub specular: BranchResult,
    /// Linear radiance `[B, 3, h, w]`.
    pub radiance: Tensor<4>,
}

#[derive(Module, Debug)]
pub struct MethodModel {
    pub diffuse: BranchNets,
    pub specular: BranchNets,
}

impl BranchNets {
    /// `branch_seed` 1 is the diffuse branch, 2 the specular one.
    fn init(config: &DenoiserConfig, method: Method, branch_seed: u64, device: &Device) -> Self {
        // Seeds per network, not per method, so a guided model starts from the very D_G / D_P a
        // G or P model of the same seed starts from.
        let s = config.seed.wrapping_mul(0x9E37_79B9).wrapping_add(branch_seed.wrapping_mul(100));
        let uses = |m: &[Method]| m.contains(&method);
        let diffuse = branch_seed == 1;
        BranchNets {
            d_g: uses(&[Method::G, Method::Guided]).then(|| config.init_column(Variant::G, diffuse, s + 1, device)),
            d_p: uses(&[Method::P, Method::Guided]).then(|| config.init_column(Variant::P, diffuse, s + 2, device)),
            d_gp: uses(&[Method::Both]).then(|| config.init_column(Variant::GP, diffuse, s + 5, device)),
            path: method.needs_descriptors().then(|| config.pathnet.init(s + 3, device)),
            e: uses(&[Method::Guided]).then(|| config.ensemble.init(s + 4, device)),
        }
    }

    /// The method these networks implement, from which of them are present.
    pub fn method(&self) -> Option<Method> {
        match (self.d_g.is_some(), self.d_p.is_some(), self.d_gp.is_some(), self.path.is_some(), self.e.is_some()) {
            (true, false, false, false, false) => Some(Method::G),
            (false, true, false, true, false) => Some(Method::P),
            (false, false, true, true, false) => Some(Method::Both),
            (true, true, false, true, true) => Some(Method::Guided),
            _ => None,
        }
    }

    pub fn forward(&self, input: BranchInput, path_weight: Tensor<4>) -> BranchResult {
        self.forward_timed(input, path_weight, None, &mut |_, _| {})
    }

    /// The branch's forward pass, reporting the wall time of each network to `lap` (the CPU
    /// backend executes eagerly, so the time around a call is that network's). `pbuf`: the
    /// P-buffer `[B, 13, H, W]` if already computed (inference computes it for the whole image
    /// first); then the PathNet is not run and the result carries no [`PathOutput`].
    pub fn forward_timed(
        &self,
        input: BranchInput,
        path_weight: Tensor<4>,
        pbuf: Option<Tensor<4>>,
        lap: &mut dyn FnMut(Part, f64),
    ) -> BranchResult {
        let (path, pbuf) = match (pbuf, &self.path) {
            (Some(pb), Some(_)) => (None, Some(pb)),
            (_, Some(net)) => {
                let path = timed(lap, Part::Path, || net.forward(input.descriptors.clone()));
                let pb = path.pixel_buffer();
                (Some(path), Some(pb))
            }
            (_, None) => (None, None),
        };
        let i_g = self
            .d_g
            .as_ref()
            .map(|d| timed(lap, Part::DG, || d.forward(Tensor::cat(vec![input.colour.clone(), input.g_block.clone()], 1), input.spp)));
        let i_p = self.d_p.as_ref().map(|d| {
            let pb = pbuf.clone().expect("D_P needs a PathNet");
            timed(lap, Part::DP, || d.forward(Tensor::cat(vec![input.colour.clone(), pb], 1), input.spp))
        });
        if let Some(d) = &self.d_gp {
            let spp = input.spp;
            let x = Tensor::cat(vec![input.colour, input.g_block, path_weight, pbuf.expect("G+P needs a PathNet")], 1);
            let output = timed(lap, Part::DP, || d.forward(x, spp));
            return BranchResult { output, i_g: None, i_p: None, weights: None, path };
        }
        match (&self.e, i_g, i_p) {
            (Some(e), Some(g), Some(p)) => {
                let Blend { output, weights } = timed(lap, Part::E, || e.forward(g.clone(), p.clone(), input.g_block, pbuf.unwrap()));
                BranchResult { output, i_g: Some(g), i_p: Some(p), weights: Some(weights), path }
            }
            (None, Some(g), None) => BranchResult { output: g.clone(), i_g: Some(g), i_p: None, weights: None, path },
            (None, None, Some(p)) => BranchResult { output: p.clone(), i_g: None, i_p: Some(p), weights: None, path },
            _ => panic!("inconsistent branch networks (method {:?})", self.method()),
        }
    }
}

/// Runs `f` and reports its wall time as `part`'s.
fn timed<T>(lap: &mut dyn FnMut(Part, f64), part: Part, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    lap(part, t.elapsed().as_secs_f64());
    out
}

/// The network a time reported by [`BranchNets::forward_timed`] belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The path-manifold module.
    Path,
    /// The column on G-buffers.
    DG,
    /// The column on P-buffers, or the both-buffers column.
    DP,
    /// E and the blend; [`MethodModel::forward_timed`] also books the recombination here.
    E,
}

impl MethodModel {
    /// Fresh weights for `method` (deterministic in `config.seed`).
    pub fn init(config: &DenoiserConfig, method: Method, device: &Device) -> Self {
        MethodModel { diffuse: BranchNets::init(config, method, 1, device), specular: BranchNets::init(config, method, 2, device) }
    }

    /// Sets γ of every U-Net column's guide gain ([`crate::mskp::guide_gain`]); KPCN columns
    /// have no guides. The weight file keeps it in `config.mskp.guide_gain_exponent`.
    pub fn set_guide_gain_exponent(&mut self, exponent: f64) {
        for b in [&mut self.diffuse, &mut self.specular] {
            for c in [&mut b.d_g, &mut b.d_p, &mut b.d_gp].into_iter().flatten() {
                if let Some(u) = &mut c.unet {
                    u.guide_gain_exponent = exponent;
                }
            }
        }
    }

    pub fn method(&self) -> Option<Method> {
        let m = self.diffuse.method();
        (m == self.specular.method()).then_some(m).flatten()
    }

    /// Runs both branches and recombines D̂ ⊙ (A + ε_a) + exp(P̂) − 1 (method.md §3, §6.1).
    pub fn forward(&self, input: InputTensors) -> MethodOutput {
        self.forward_timed(input, None, &mut |_, _| {})
    }

    /// [`Self::forward`] with each network's time reported to `lap` and, optionally, the
    /// (diffuse, specular) P-buffers already computed (see [`BranchNets::forward_timed`]).
    pub fn forward_timed(&self, input: InputTensors, pbufs: Option<[Tensor<4>; 2]>, lap: &mut dyn FnMut(Part, f64)) -> MethodOutput {
        let albedo = input.diffuse.g_block.clone().narrow(1, G_ALBEDO, 3);
        let [pd, ps] = pbufs.map_or([None, None], |[d, s]| [Some(d), Some(s)]);
        let diffuse = self.diffuse.forward_timed(input.diffuse, input.path_weight.clone(), pd, lap);
        let specular = self.specular.forward_timed(input.specular, input.path_weight, ps, lap);
        let radiance = timed(lap, Part::E, || recombine(diffuse.output.clone(), specular.output.clone(), albedo));
        MethodOutput { diffuse, specular, radiance }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ensemble::EnsembleConfig;
    use crate::kpcn::KpcnConfig;
    use crate::pathnet::PathNetConfig;
    use crate::test_util::to_vec;

    fn tiny() -> DenoiserConfig {
        DenoiserConfig::new(
            KpcnConfig::new(34).with_depth(2).with_width(8).with_conv_kernel(3).with_filter_size(3),
            PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 8]).with_convs_per_block(1).with_out_hidden(8),
            EnsembleConfig::new().with_depth(2).with_width(6).with_conv_kernel(3),
        )
    }

    fn inputs(b: usize, s: usize, h: usize, w: usize, d: &Device) -> InputTensors {
        let r = |dims: [usize; 4], k: f32| Tensor::<4>::ones(dims, d).mul_scalar(k);
        let desc = Tensor::<5>::ones([b, s, 36, h, w], d).mul_scalar(0.3);
        let g_block = r([b, 24, h, w], 0.5);
        InputTensors {
            diffuse: BranchInput { colour: r([b, 10, h, w], 0.7), g_block: g_block.clone(), descriptors: desc.clone(), spp: s },
            specular: BranchInput { colour: r([b, 10, h, w], 0.2), g_block, descriptors: desc, spp: s },
            path_weight: r([b, 1, h, w], -0.1),
        }
    }

    /// Every method builds the networks it needs and nothing else, runs, and gives finite
    /// radiance at the documented output size.
    #[test]
    fn every_method_runs_with_only_its_networks() {
        let d = crate::cpu_device();
        let c = tiny();
        for m in Method::ALL {
            let model = MethodModel::init(&c, m, &d);
            assert_eq!(model.method(), Some(m));
            assert_eq!(model.diffuse.e.is_some(), m == Method::Guided);
            let out = model.forward(inputs(2, 3, 10, 9, &d));
            let o = 2 * c.margin();
            assert_eq!(out.radiance.dims(), [2, 3, 10 - o, 9 - o], "{m}");
            assert_eq!(out.diffuse.weights.is_some(), m == Method::Guided);
            assert!(to_vec(out.radiance).iter().all(|x| x.is_finite()), "{m}");
            assert_eq!(Method::parse(m.name()), Some(m));
        }
    }

    /// A guided model starts from the same D_G a G model of the same seed starts from.
    #[test]
    fn guided_shares_initial_columns_with_g() {
        let d = crate::cpu_device();
        let g = MethodModel::init(&tiny(), Method::G, &d);
        let guided = MethodModel::init(&tiny(), Method::Guided, &d);
        let w = |m: &MethodModel| to_vec(m.specular.d_g.as_ref().unwrap().net.as_ref().unwrap().layers[0].weight.val());
        assert_eq!(w(&g), w(&guided));
    }
}
