//! The sizes of the pixel-guidance framework (method.md §6) — per branch the denoising columns
//! (D_G on the G-buffer, D_P on the P-buffer, or the both-buffers column), one PathNet and the
//! ensembling network E — and the size presets. The model itself is [`crate::method::MethodModel`].

use burn::config::Config;
use burn::tensor::{Device, Tensor};

use crate::column::Column;
use crate::ensemble::EnsembleConfig;
use crate::kpcn::{KpcnConfig, Variant};
use crate::mskp::{EdgeStopping, GuideGroup, MsKpConfig, ScaleCompositor};
use crate::pathnet::PathNetConfig;

/// Sizes of every network of one branch (both branches use the same sizes).
/// The columns' `in_channels` are ignored: each column gets its variant's count.
#[derive(Config, Debug)]
pub struct DenoiserConfig {
    /// The KPCN columns' sizes (used when `mskp` is `None`).
    pub kpcn: KpcnConfig,
    pub pathnet: PathNetConfig,
    pub ensemble: EnsembleConfig,
    /// Columns are multi-scale kernel-predicting U-Nets of these sizes instead of KPCNs.
    #[config(default = "None")]
    pub mskp: Option<MsKpConfig>,
    /// D_P's U-Net level widths where they differ from `mskp.widths` (as many levels): a guided
    /// model can then join a D_G trained wider than its D_P (docs/journal/denoiser.md, "Wider columns").
    /// The both-buffers column keeps `mskp.widths`.
    #[config(default = "None")]
    pub p_widths: Option<Vec<usize>>,
    /// Seed of every initial weight (same seed → same weights).
    #[config(default = 0)]
    pub seed: u64,
}

impl DenoiserConfig {
    /// Full paper size (method.md §3, §4.2, §6.1).
    pub fn paper() -> Self {
        Self::new(KpcnConfig::new(Variant::G.in_channels()), PathNetConfig::new(), EnsembleConfig::new())
    }

    /// Every channel width halved; depths, kernels, filter size (so the margin) and the
    /// 12-channel P-buffer, which is part of the method, unchanged.
    pub fn halved(mut self) -> Self {
        self.kpcn.width /= 2;
        self.pathnet.embed_width /= 2;
        self.pathnet.unet_widths.iter_mut().for_each(|w| *w /= 2);
        self.pathnet.out_hidden /= 2;
        self.ensemble.width /= 2;
        if let Some(m) = &mut self.mskp {
            m.widths.iter_mut().for_each(|w| *w /= 2);
        }
        if let Some(w) = &mut self.p_widths {
            w.iter_mut().for_each(|w| *w /= 2);
        }
        self
    }

    /// The paper's "half" model (KPCN 50, E 25); halving the PathNet too is our choice.
    pub fn paper_half() -> Self {
        Self::paper().halved()
    }

    /// `default` halved the same way: the guided-half of our comparison.
    pub fn half() -> Self {
        Self::cpu_default().halved()
    }

    /// The KPCN sized for this 2-core CPU (the `default` until the backbone race of
    /// docs/training.md): 7 layers of 3×3, width 48, 13×13 filters (margin 7 px); PathNet at
    /// quarter width with 2 convs per U-Net block; E: 5 layers 3×3 of width 24.
    pub fn kpcn_cpu() -> Self {
        Self::new(
            KpcnConfig::new(Variant::G.in_channels()).with_depth(7).with_width(48).with_conv_kernel(3).with_filter_size(13),
            PathNetConfig::new().with_embed_width(32).with_unet_widths(vec![32, 48, 64]).with_convs_per_block(2).with_out_hidden(32),
            EnsembleConfig::new().with_depth(5).with_width(24).with_conv_kernel(3),
        )
    }

    /// The default (docs/denoiser-design.md, "The multi-scale backbone"; chosen by the
    /// equal-time race of docs/training.md): D_G, D_P and the both-buffers column are
    /// kernel-predicting U-Nets of 5 levels (24 … 80 channels) filtering at 3 scales with 5×5
    /// kernels; the PathNet and E are slimmer than the KPCN preset's, which the U-Net's own
    /// context makes affordable. The KPCN sizes in `kpcn` are unused placeholders.
    pub fn cpu_default() -> Self {
        Self::new(
            Self::kpcn_cpu().kpcn,
            PathNetConfig::new().with_embed_width(24).with_unet_widths(vec![16, 24, 32]).with_convs_per_block(2).with_out_hidden(24),
            EnsembleConfig::new().with_depth(5).with_width(16).with_conv_kernel(3),
        )
        .with_mskp(Some(MsKpConfig::new(Variant::G.in_channels())))
    }

    /// `default` with kernels at all five U-Net levels composited by Vogels et al.'s low-band
    /// swap ([`ScaleCompositor::LowPassSwap`]). Opt-in, not the default: that compositor is the
    /// subject of US patent 10,699,382 (docs/method.md §12), which the default's convex blend
    /// was chosen to stay clear of; measured in docs/journal/denoiser.md ("The swap models").
    pub fn swap() -> Self {
        let mut c = Self::cpu_default();
        c.mskp = c.mskp.map(|m| m.with_kernel_scales(5).with_compositor(ScaleCompositor::LowPassSwap));
        c
    }

    /// `default` with kernels at all five levels and edge-stopping kernels guided by the colour
    /// (brighter taps only) and the auxiliary features (normal, depth and albedo in D_G, f_P in
    /// D_P; [`crate::mskp`]) with joint-bilateral upsampling: the convex blend, so clear of the
    /// swap's patent.
    pub fn edge() -> Self {
        let mut c = Self::cpu_default();
        c.mskp = c.mskp.map(|m| m.with_kernel_scales(5).with_edge_stopping(EdgeStopping::FeaturesAndColour));
        c
    }

    /// `edge` with the colour guides measured in units of the colour's noise instead of
    /// brighter-only log differences, by a test that is two-sided at 2 spp and fades toward
    /// Rousselle's one-sided one as the samples grow, except where a pixel is black
    /// ([`EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack`]). Weight files of the
    /// one-sided (2026-11-25, afternoon), the two-sided (evening) and the fading form
    /// (2026-11-26, morning) keep theirs: the variant is stored in each file's config.
    pub fn edge_noise() -> Self {
        let mut c = Self::edge();
        c.mskp = c.mskp.map(|m| m.with_edge_stopping(EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack));
        c
    }

    /// Peak learning rate of the pretraining stage: the highest rate measured stable for the
    /// backbone (docs/journal/training.md, "Learning rate"). The U-Net trains at 1e-3 (3e-3 diverged);
    /// the KPCN stays at the paper's 1e-4 (1e-3 diverged, 3e-4 oscillated in the race).
    pub fn peak_lr(&self) -> f64 {
        if self.mskp.is_some() {
            1e-3
        } else {
            1e-4
        }
    }

    pub fn kpcn_for(&self, v: Variant) -> KpcnConfig {
        let mut c = self.kpcn.clone();
        c.in_channels = v.in_channels();
        c
    }

    pub fn mskp_for(&self, v: Variant) -> Option<MsKpConfig> {
        self.mskp_for_branch(v, true)
    }

    /// [`Self::mskp_for`] for the diffuse (`diffuse`) or the specular branch: the guides differ
    /// only under [`EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack`].
    pub fn mskp_for_branch(&self, v: Variant, diffuse: bool) -> Option<MsKpConfig> {
        self.mskp.clone().map(|mut c| {
            c.in_channels = v.in_channels();
            if let (Variant::P, Some(w)) = (v, &self.p_widths) {
                c.widths = w.clone();
            }
            if c.edge_stopping != EdgeStopping::Off {
                c.guides = edge_guides(v, c.edge_stopping, diffuse);
            }
            c
        })
    }
}

/// The edge-stopping guides of a column's input (channel offsets of kpcn::channels): with
/// `colour`, the colour it filters as log(1 + c), brighter taps only (a symmetric colour distance
/// kept every firefly: validation relMSE 0.41–1.07 where plain kernels had 0.015); then what the
/// variant adds: normal, depth (×20: it is path length over 10 scene radii, so neighbours differ
/// by hundredths) and albedo for G, the path features f_P for P.
fn edge_guides(v: Variant, stopping: EdgeStopping, diffuse: bool) -> Vec<GuideGroup> {
    use crate::kpcn::channels::*;
    let colour = match stopping {
        EdgeStopping::FeaturesAndColour => Some(GuideGroup::new(0, 3, 1.0, true).brighter_only()),
        // Channel 3 is the variance of the colour's mean in the colour's own units
        // (preprocess.rs). Two guides: by the pixel's own variance (sharp where it is reliable,
        // at high spp) and by the pooled one (reliable at 2 spp, where most pixels report 0;
        // mskp::pooled_variance). The pooled one starts at e^−3, where a jump of 3σ in every
        // channel keeps ~30 % of a tap's weight and one of 10σ none, so it acts from the first
        // step; the own one at e^−5, to be raised where the network finds it reliable.
        EdgeStopping::FeaturesAndNoisyColour
        | EdgeStopping::FeaturesAndTwoSidedNoisyColour
        | EdgeStopping::FeaturesAndFadingTwoSidedNoisyColour
        | EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack => {
            let mut own = GuideGroup::new(0, 3, 1.0, false).with_variance(3).with_init_log_strength(-5.0);
            let mut pooled = GuideGroup::new(0, 3, 1.0, false).with_pooled_variance(3).with_init_log_strength(-3.0);
            match stopping {
                EdgeStopping::FeaturesAndTwoSidedNoisyColour => (own, pooled) = (own.two_sided(), pooled.two_sided()),
                EdgeStopping::FeaturesAndFadingTwoSidedNoisyColour => (own, pooled) = (own.two_sided_fading(), pooled.two_sided_fading()),
                // Black diffuse light is an accident of few samples (veach-ajar at 4 spp); black
                // specular light is mostly a surface without a specular lobe, a fact at any
                // sample count (the brick wall beside wire-fence's glinting wires: doubting it
                // there took g from 0.0063 to 0.0077 at 32 spp, docs/denoiser.md).
                EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack if diffuse => {
                    (own, pooled) = (own.two_sided_fading_doubting_black(), pooled.two_sided_fading_doubting_black())
                }
                EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack => {
                    (own, pooled) = (own.two_sided_fading(), pooled.two_sided_fading())
                }
                _ => {}
            }
            return [own, pooled].into_iter().chain(edge_guides(v, EdgeStopping::Features, diffuse)).collect();
        }
        EdgeStopping::Features | EdgeStopping::Off => None,
    };
    let g = COLOUR_BLOCK;
    let g_block =
        vec![GuideGroup::new(g, 3, 1.0, false), GuideGroup::new(g + 10, 1, 20.0, false), GuideGroup::new(g + G_ALBEDO, 3, 1.0, false)];
    let f_p = |at: usize| vec![GuideGroup::new(at, P_FEATURES, 1.0, false)];
    let features = match v {
        Variant::G => g_block,
        Variant::P => f_p(COLOUR_BLOCK),
        Variant::GP => g_block.into_iter().chain(f_p(COLOUR_BLOCK + G_BLOCK + 1)).collect(),
    };
    colour.into_iter().chain(features).collect()
}

impl DenoiserConfig {
    /// A fresh column of `variant` for the diffuse (`diffuse`) or specular branch (deterministic
    /// in `seed`).
    pub fn init_column(&self, v: Variant, diffuse: bool, seed: u64, device: &Device) -> Column {
        match self.mskp_for_branch(v, diffuse) {
            Some(c) => Column::mskp(c.init(seed, device)),
            None => self.kpcn_for(v).init(seed, device),
        }
    }

    /// Forward multiply-accumulates per output pixel of one column.
    pub fn column_macs(&self, v: Variant) -> u64 {
        match self.mskp_for(v) {
            Some(c) => c.macs_per_pixel(),
            None => self.kpcn_for(v).macs_per_pixel(),
        }
    }

    /// Pixels lost per side between the input patch and the output (the column's margin).
    pub fn margin(&self) -> usize {
        self.mskp.as_ref().map_or_else(|| self.kpcn.margin(), |m| m.margin)
    }

    /// Receptive radius of a column (pixels per side): an output pixel depends on no input pixel
    /// farther away. A KPCN's is its margin (valid convolutions); the U-Net's reaches beyond.
    pub fn column_radius(&self) -> usize {
        self.mskp.as_ref().map_or_else(|| self.kpcn.margin(), |m| m.radius().max(m.margin))
    }

    /// Multiple that window origins must keep for the columns' pooling grids (1 for a KPCN).
    pub fn column_alignment(&self) -> usize {
        self.mskp.as_ref().map_or(1, MsKpConfig::alignment)
    }

    /// Forward multiply-accumulates per output pixel of the whole guided framework (both
    /// branches: D_G, D_P, PathNet, E) at `spp` samples per pixel (a training step costs
    /// roughly 3× this).
    pub fn macs_per_pixel(&self, spp: usize) -> u64 {
        let per_branch =
            self.column_macs(Variant::G) + self.column_macs(Variant::P) + self.pathnet.macs_per_pixel(spp) + self.ensemble.macs_per_pixel();
        2 * per_branch
    }
}

/// A named set of network sizes, as `pixguide train --preset` takes it and weight files record
/// it: `default` (multi-scale U-Net columns), `half` (of default), `swap` (default with the
/// patented low-band-swap compositor at five scales, opt-in), `edge` (five scales,
/// edge-stopping kernels), `edge-noise` (its colour guide noise-normalised), `kpcn` (the
/// CPU-sized KPCN), `paper-half` or `paper`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Preset {
    Default,
    Half,
    Swap,
    Edge,
    EdgeNoise,
    Kpcn,
    PaperHalf,
    Paper,
}

impl Preset {
    pub const ALL: [Preset; 8] =
        [Preset::Default, Preset::Half, Preset::Swap, Preset::Edge, Preset::EdgeNoise, Preset::Kpcn, Preset::PaperHalf, Preset::Paper];

    /// The name in weight files (`pixguide.preset`) and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Default => "default",
            Preset::Half => "half",
            Preset::Swap => "swap",
            Preset::Edge => "edge",
            Preset::EdgeNoise => "edge-noise",
            Preset::Kpcn => "kpcn",
            Preset::PaperHalf => "paper-half",
            Preset::Paper => "paper",
        }
    }

    pub fn config(self) -> DenoiserConfig {
        match self {
            Preset::Default => DenoiserConfig::cpu_default(),
            Preset::Half => DenoiserConfig::half(),
            Preset::Swap => DenoiserConfig::swap(),
            Preset::Edge => DenoiserConfig::edge(),
            Preset::EdgeNoise => DenoiserConfig::edge_noise(),
            Preset::Kpcn => DenoiserConfig::kpcn_cpu(),
            Preset::PaperHalf => DenoiserConfig::paper_half(),
            Preset::Paper => DenoiserConfig::paper(),
        }
    }
}

crate::names::named!(Preset, "preset");

/// Inputs of one branch, all at the input patch size H × W.
#[derive(Clone, Debug)]
pub struct BranchInput {
    /// D (diffuse) or P (specular) block `[B, 10, H, W]`.
    pub colour: Tensor<4>,
    /// G-buffer block `[B, 24, H, W]`.
    pub g_block: Tensor<4>,
    /// Normalised path descriptors `[B, S, 36, H, W]`.
    pub descriptors: Tensor<5>,
    /// Samples per pixel of the colour (S may be 0 where no descriptors were rendered).
    pub spp: usize,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::{l1, path_disentangling_loss};
    use crate::method::{Method, MethodModel};
    use crate::preprocess::InputTensors;
    use crate::rng::SplitMix64;
    use crate::test_util::{tensor, to_vec};
    use crate::{cpu_device, cpu_training_device};
    use burn::grad_clipping::GradientClippingConfig;
    use burn::optim::{AdamConfig, GradientsParams};

    pub fn tiny() -> DenoiserConfig {
        DenoiserConfig::new(
            KpcnConfig::new(34).with_depth(2).with_width(8).with_conv_kernel(3).with_filter_size(3),
            PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 8]).with_convs_per_block(1).with_out_hidden(8),
            EnsembleConfig::new().with_depth(2).with_width(6).with_conv_kernel(3),
        )
    }

    /// `tiny` with multi-scale U-Net columns.
    pub fn tiny_mskp() -> DenoiserConfig {
        tiny().with_mskp(Some(MsKpConfig::new(34).with_widths(vec![6, 8, 8]).with_kernel_scales(2).with_filter_size(3).with_margin(2)))
    }

    fn random_input(b: usize, s: usize, h: usize, w: usize, rng: &mut SplitMix64, d: &Device) -> InputTensors {
        let mut r = |n: usize| -> Vec<f64> { (0..n).map(|_| rng.next_f64()).collect() };
        let mut branch = || BranchInput {
            colour: tensor(&r(b * 10 * h * w), [b, 10, h, w], d),
            g_block: tensor(&r(b * 24 * h * w), [b, 24, h, w], d),
            descriptors: tensor(&r(b * s * 36 * h * w), [b, s, 36, h, w], d),
            spp: s,
        };
        let (diffuse, specular) = (branch(), branch());
        InputTensors { diffuse, specular, path_weight: Tensor::zeros([b, 1, h, w], d) }
    }

    fn weights_of(m: &MethodModel) -> Vec<f64> {
        let mut v = Vec::new();
        for br in [&m.diffuse, &m.specular] {
            let (g, p) = (br.d_g.as_ref().unwrap(), br.d_p.as_ref().unwrap());
            match (&g.net, &g.unet) {
                (Some(net), _) => v.extend(to_vec(net.layers[0].weight.val())),
                (_, Some(u)) => v.extend(to_vec(u.heads[0].weight.val())),
                _ => unreachable!(),
            }
            v.extend(to_vec(
                p.net.as_ref().map_or_else(|| p.unet.as_ref().unwrap().down[0].layers[1].weight.val(), |n| n.layers[1].weight.val()),
            ));
            let path = br.path.as_ref().unwrap();
            v.extend(to_vec(path.head.layers[0].weight.val()));
            v.extend(to_vec(path.head.layers[0].bias.val()));
            v.extend(to_vec(br.e.as_ref().unwrap().net.layers[0].weight.val()));
        }
        v
    }

    #[test]
    fn same_seed_same_weights() {
        let d = cpu_device();
        for cfg in [tiny(), tiny_mskp()] {
            let a = weights_of(&MethodModel::init(&cfg, Method::Guided, &d));
            let b = weights_of(&MethodModel::init(&cfg, Method::Guided, &d));
            let c = weights_of(&MethodModel::init(&cfg.clone().with_seed(1), Method::Guided, &d));
            assert_eq!(a, b);
            assert_ne!(a, c);
        }
        // Branches and networks draw from distinct streams.
        let m = MethodModel::init(&tiny(), Method::Guided, &d);
        let w1 = |c: &Option<Column>| to_vec(c.as_ref().unwrap().net.as_ref().unwrap().layers[1].weight.val());
        assert_ne!(w1(&m.diffuse.d_g), w1(&m.specular.d_g));
    }

    #[test]
    fn presets_shapes_and_costs() {
        for p in Preset::ALL {
            assert_eq!(p.name().parse::<Preset>().unwrap(), p);
            assert!(p.config().macs_per_pixel(8) > 0);
        }
        let paper = DenoiserConfig::paper();
        let paper_half = DenoiserConfig::paper_half();
        let cpu = DenoiserConfig::kpcn_cpu();
        let half = DenoiserConfig::kpcn_cpu().halved();
        // Halving widths cuts the width² terms by 4 and the input/output layers by 2: between.
        for (big, small) in [(&paper, &paper_half), (&cpu, &half)] {
            let (b, s) = (big.macs_per_pixel(8) as f64, small.macs_per_pixel(8) as f64);
            assert!(s < b / 2.0 && s > b / 4.5, "{s} vs {b}");
            assert_eq!(big.margin(), small.margin());
        }
        assert!(cpu.macs_per_pixel(8) < paper_half.macs_per_pixel(8));
        assert_eq!((paper_half.kpcn.width, paper_half.pathnet.embed_width, paper_half.ensemble.width), (50, 32, 25));
        assert_eq!(
            (half.kpcn.width, half.pathnet.unet_widths.clone(), half.pathnet.out_hidden, half.ensemble.width),
            (24, vec![16, 24, 32], 16, 12)
        );
        let (default, default_half) = (DenoiserConfig::cpu_default(), DenoiserConfig::half());
        assert_eq!(default_half.mskp.as_ref().map(|m| m.widths.clone()), Some(vec![12, 16, 24, 32, 40]));
        let (b, s) = (default.macs_per_pixel(8) as f64, default_half.macs_per_pixel(8) as f64);
        assert!(s < b / 2.0 && s > b / 4.5, "{s} vs {b}");
        assert!("huge".parse::<Preset>().is_err());
        // The multi-scale preset's targets: ≤ 0.5 M MAC per pixel for the whole
        // guided model at 8 spp, and a column seeing ≥ 64 px.
        let ms = DenoiserConfig::cpu_default();
        assert!(ms.macs_per_pixel(8) <= 500_000, "{}", ms.macs_per_pixel(8));
        assert!(2 * ms.column_radius() + 1 >= 64);
        assert!(ms.column_radius() > ms.margin() && ms.column_alignment() == 16);
        assert_eq!(cpu.column_radius(), cpu.margin());
    }

    /// Full two-branch guided forward on hostile inputs: every output finite, shapes as
    /// documented, for both backbones.
    #[test]
    fn full_forward_is_finite_on_hostile_input() {
        let d = cpu_device();
        for cfg in [tiny(), tiny_mskp()] {
            let m = MethodModel::init(&cfg, Method::Guided, &d);
            let mut rng = SplitMix64::new(9);
            let (b, s, h, w) = (1, 2, 12, 12);
            let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e6, 0.0];
            let mut input = random_input(b, s, h, w, &mut rng, &d);
            let v: Vec<f64> = (0..b * 24 * h * w).map(|i| specials[i % 5]).collect();
            input.diffuse.g_block = tensor(&v, [b, 24, h, w], &d);
            input.specular = BranchInput {
                colour: Tensor::zeros([b, 10, h, w], &d),
                g_block: Tensor::zeros([b, 24, h, w], &d),
                descriptors: Tensor::zeros([b, s, 36, h, w], &d),
                spp: s,
            };
            let out = m.forward(input);
            let o = h - 2 * cfg.margin();
            assert_eq!(out.radiance.dims(), [b, 3, o, o]);
            for t in [out.radiance, out.diffuse.output, out.specular.output, out.diffuse.weights.unwrap()] {
                assert!(to_vec(t).iter().all(|x| x.is_finite()));
            }
        }
    }

    /// The `edge-noise` preset's colour guides doubt a black centre only in the diffuse branch
    /// of a model built from it: a black specular pixel is mostly a surface without a specular
    /// lobe (docs/journal/denoiser.md, "Doubting black diffuse pixels").
    #[test]
    fn edge_noise_preset_doubts_black_only_in_the_diffuse_branch() {
        let model = MethodModel::init(&DenoiserConfig::edge_noise(), Method::Guided, &cpu_device());
        let colour_doubts = |b: &crate::method::BranchNets| {
            [&b.d_g, &b.d_p].map(|c| {
                let guides = &c.as_ref().unwrap().unet.as_ref().unwrap().guides;
                let colour: Vec<_> = guides.iter().filter(|g| g.variance.is_some()).collect();
                assert_eq!(colour.len(), 2, "own and pooled colour guides");
                colour.iter().map(|g| g.doubt_black && g.two_sided_fades).collect::<Vec<_>>()
            })
        };
        assert_eq!(colour_doubts(&model.diffuse), [vec![true, true], vec![true, true]]);
        assert_eq!(colour_doubts(&model.specular), [vec![false, false], vec![false, false]]);
    }

    /// A tiny guided model trained 40 Adam steps on one fixed batch (all losses of the joint
    /// stage) lowers its L1, for both backbones. Threshold 0.8× initial: the fit is a
    /// memorisation task the tiny model reaches far below that within 40 steps at lr 1e-2, yet an
    /// unused gradient or a broken optimizer step leaves the loss where it started.
    #[test]
    fn few_adam_steps_lower_the_loss() {
        let d = cpu_training_device();
        for cfg in [tiny(), tiny_mskp()] {
            let mut model = MethodModel::init(&cfg, Method::Guided, &d);
            let mut rng = SplitMix64::new(21);
            let (b, s, h, w) = (2, 2, 12, 12);
            let input = random_input(b, s, h, w, &mut rng, &d);
            let o = h - 2 * cfg.margin();
            let t: Vec<f64> = (0..b * 3 * o * o).map(|i| 0.2 + 0.6 * ((i % 7) as f64 / 7.0)).collect();
            let target = tensor(&t, [b, 3, o, o], &d);
            let mut optim = AdamConfig::new().with_epsilon(1e-8).with_grad_clipping(Some(GradientClippingConfig::Value(1.0))).init();
            let mut losses = Vec::new();
            for _ in 0..40 {
                let out = model.forward(input.clone());
                let br = out.diffuse;
                let fit = l1(br.output.clone(), target.clone()) + l1(br.i_g.unwrap(), target.clone()) + l1(br.i_p.unwrap(), target.clone());
                losses.push(to_vec(fit.clone())[0]);
                let loss = fit + path_disentangling_loss(br.path.unwrap().samples, target.clone(), &mut rng).mul_scalar(0.1);
                let grads = GradientsParams::from_grads(loss.backward(), &model);
                model = optim.step(1e-2, model, grads);
            }
            let (first, last) = (losses[0], *losses.last().unwrap());
            assert!(last.is_finite() && last < 0.8 * first, "loss {first} → {last}");
        }
    }
}
