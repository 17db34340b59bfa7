//! Data augmentation by the 8 symmetries of the square (flips, 90° rotations, transposes),
//! applied to a training patch consistently: every buffer is moved with the image, the
//! screen-space normals are rotated with it, and the forward-difference gradient channels are
//! recomputed from the moved planes — including across the patch edge, from the image around the
//! patch — so an augmented patch is exactly the patch of the augmented image.
//!
//! A symmetry T maps patch-local coordinates (x, y) (y down) by: transpose if bit 0
//! ((x, y) → (y, x)), then mirror x if bit 1, then mirror y if bit 2. The augmented patch is
//! J(T(q)) = I(q).

use crate::kpcn::channels::{COLOUR_BLOCK, G_BLOCK};
use crate::preprocess::{PreparedImage, PreparedTarget, DESCRIPTOR_CHANNELS};

/// One of the 8 symmetries of the square; 0 is the identity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dihedral(pub u8);

impl Dihedral {
    pub const IDENTITY: Dihedral = Dihedral(0);

    pub fn all() -> impl Iterator<Item = Dihedral> {
        (0..8).map(Dihedral)
    }

    fn transpose(self) -> bool {
        self.0 & 1 != 0
    }
    fn mirror_x(self) -> bool {
        self.0 & 2 != 0
    }
    fn mirror_y(self) -> bool {
        self.0 & 4 != 0
    }

    /// T(x, y) in a square of side `p` (coordinates may lie one pixel outside it).
    pub fn forward(self, x: isize, y: isize, p: usize) -> (isize, isize) {
        let last = p as isize - 1;
        let (mut x, mut y) = if self.transpose() { (y, x) } else { (x, y) };
        if self.mirror_x() {
            x = last - x;
        }
        if self.mirror_y() {
            y = last - y;
        }
        (x, y)
    }

    /// T⁻¹(u, v): undo the mirrors, then the transpose.
    pub fn source(self, u: isize, v: isize, p: usize) -> (isize, isize) {
        let last = p as isize - 1;
        let u = if self.mirror_x() { last - u } else { u };
        let v = if self.mirror_y() { last - v } else { v };
        if self.transpose() {
            (v, u)
        } else {
            (u, v)
        }
    }

    /// The symmetry that undoes this one.
    pub fn inverse(self) -> Dihedral {
        // T = My∘Mx∘Tr; T⁻¹ = Tr∘Mx∘My, which is Tr'∘... with the mirrors swapped when transposed.
        if self.transpose() {
            Dihedral(1 | (u8::from(self.mirror_y()) << 1) | (u8::from(self.mirror_x()) << 2))
        } else {
            self
        }
    }

    /// A screen-space normal's (x right, y up) components after the image moves with T.
    pub fn normal(self, nx: f32, ny: f32) -> (f32, f32) {
        // In image axes (right, down) the vector is (nx, −ny); it moves like a displacement.
        let (mut a, mut b) = (nx, -ny);
        if self.transpose() {
            std::mem::swap(&mut a, &mut b);
        }
        if self.mirror_x() {
            a = -a;
        }
        if self.mirror_y() {
            b = -b;
        }
        (a, -b)
    }
}

/// Base planes of a block and the positions of their gradient planes: (base plane, x-gradient
/// plane, y-gradient plane) triples; the rest (variances) are moved as they are.
const COLOUR_GRADIENTS: [(usize, usize, usize); 3] = [(0, 4, 7), (1, 5, 8), (2, 6, 9)];
const G_GRADIENTS: [(usize, usize, usize); 7] = [(0, 4, 7), (1, 5, 8), (2, 6, 9), (10, 12, 13), (14, 18, 21), (15, 19, 22), (16, 20, 23)];
const G_NORMAL: usize = 0;

/// Where a patch's descriptors come from.
pub trait DescriptorSource {
    /// The normalised descriptors `[S, 36, len]` of `pixels` (indices into the image).
    fn columns(&self, pixels: &[usize]) -> Vec<f32>;
}

/// Normalised descriptor planes `[S_img, 36, H·W]` in memory, and the sample count to cut
/// (a prefix).
pub struct Planes<'a> {
    pub data: &'a [f32],
    pub spp: usize,
    pub pixels: usize,
}

impl DescriptorSource for Planes<'_> {
    fn columns(&self, pixels: &[usize]) -> Vec<f32> {
        (0..self.spp * DESCRIPTOR_CHANNELS).flat_map(|plane| pixels.iter().map(move |&i| self.data[plane * self.pixels + i])).collect()
    }
}

/// The `p × p` patch at (x, y) of `img`, moved by `t`, its gradients recomputed (see the module
/// comment), with the descriptors of `descriptors` if given.
pub fn cut_image(
    img: &PreparedImage,
    descriptors: Option<&dyn DescriptorSource>,
    x: usize,
    y: usize,
    p: usize,
    t: Dihedral,
) -> PreparedImage {
    let (w, h) = (img.width, img.height);
    assert!(x + p <= w && y + p <= h, "patch {p}² at ({x},{y}) outside {w}×{h}");
    let n = w * h;
    // Source pixel index for augmented coordinates (u, v) ∈ [−1, p)², or None outside the image.
    let src = |u: isize, v: isize| -> Option<usize> {
        let (sx, sy) = t.source(u, v, p);
        let (ix, iy) = (x as isize + sx, y as isize + sy);
        (ix >= 0 && iy >= 0 && (ix as usize) < w && (iy as usize) < h).then(|| iy as usize * w + ix as usize)
    };
    let index: Vec<usize> = (0..p as isize).flat_map(|v| (0..p as isize).map(move |u| (u, v))).map(|(u, v)| src(u, v).unwrap()).collect();
    let moved = |buf: &[f32], plane: usize| -> Vec<f32> { index.iter().map(|&i| buf[plane * n + i]).collect() };
    let block = |buf: &[f32], planes: usize, grads: &[(usize, usize, usize)], normal: Option<usize>| -> Vec<f32> {
        let mut out = vec![0.0f32; planes * p * p];
        let is_grad = |c: usize| grads.iter().any(|g| g.1 == c || g.2 == c);
        for c in (0..planes).filter(|&c| !is_grad(c)) {
            out[c * p * p..(c + 1) * p * p].copy_from_slice(&moved(buf, c));
        }
        // The value of base plane c at augmented (u, v), reading outside the patch as needed.
        let value = |c: usize, u: isize, v: isize| -> Option<f32> {
            let i = src(u, v)?;
            Some(match normal {
                Some(n0) if (n0..n0 + 2).contains(&c) => {
                    let (a, b) = t.normal(buf[n0 * n + i], buf[(n0 + 1) * n + i]);
                    if c == n0 {
                        a
                    } else {
                        b
                    }
                }
                _ => buf[c * n + i],
            })
        };
        if let Some(n0) = normal {
            for v in 0..p {
                for u in 0..p {
                    for c in [n0, n0 + 1] {
                        out[c * p * p + v * p + u] = value(c, u as isize, v as isize).unwrap();
                    }
                }
            }
        }
        for &(base, gx, gy) in grads {
            for v in 0..p as isize {
                for u in 0..p as isize {
                    let here = value(base, u, v).unwrap();
                    let k = (v as usize) * p + u as usize;
                    out[gx * p * p + k] = value(base, u - 1, v).map_or(0.0, |l| here - l);
                    out[gy * p * p + k] = value(base, u, v - 1).map_or(0.0, |a| here - a);
                }
            }
        }
        out
    };
    let descriptors = descriptors.map(|d| d.columns(&index));
    PreparedImage {
        width: p,
        height: p,
        spp: img.spp,
        diffuse: block(&img.diffuse, COLOUR_BLOCK, &COLOUR_GRADIENTS, None),
        specular: block(&img.specular, COLOUR_BLOCK, &COLOUR_GRADIENTS, None),
        g_block: block(&img.g_block, G_BLOCK, &G_GRADIENTS, Some(G_NORMAL)),
        path_weight: moved(&img.path_weight, 0),
        descriptors,
        records: None,
        passthrough: if img.passthrough.is_empty() { Vec::new() } else { index.iter().map(|&i| img.passthrough[i]).collect() },
    }
}

/// The `o × o` target window at (x, y), moved by `t` (plain planes: no vectors, no gradients).
pub fn cut_target(t_img: &PreparedTarget, x: usize, y: usize, o: usize, t: Dihedral) -> PreparedTarget {
    let w = t_img.width;
    let n = w * t_img.height;
    let index: Vec<usize> = (0..o as isize)
        .flat_map(|v| (0..o as isize).map(move |u| (u, v)))
        .map(|(u, v)| {
            let (sx, sy) = t.source(u, v, o);
            (y + sy as usize) * w + x + sx as usize
        })
        .collect();
    let moved = |buf: &[f32]| -> Vec<f32> { (0..3).flat_map(|c| index.iter().map(move |&i| buf[c * n + i])).collect() };
    PreparedTarget { width: o, height: o, diffuse: moved(&t_img.diffuse), specular: moved(&t_img.specular), total: moved(&t_img.total) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn planes<'a>(img: &PreparedImage, data: &'a [f32], spp: usize) -> Planes<'a> {
        Planes { data, spp, pixels: img.width * img.height }
    }

    fn random_image(w: usize, h: usize, s: usize, seed: u64) -> PreparedImage {
        let mut rng = SplitMix64::new(seed);
        let mut r = |k: usize| -> Vec<f32> { (0..k).map(|_| rng.next_f64() as f32 * 2.0 - 1.0).collect() };
        let n = w * h;
        let mut img = PreparedImage {
            width: w,
            height: h,
            spp: s,
            diffuse: r(COLOUR_BLOCK * n),
            specular: r(COLOUR_BLOCK * n),
            g_block: r(G_BLOCK * n),
            path_weight: r(n),
            descriptors: Some(r(s * DESCRIPTOR_CHANNELS * n)),
            records: None,
            passthrough: (0..n).map(|i| i % 7 == 0).collect(),
        };
        // Make the stored gradients the forward differences of the planes, as preprocessing does.
        let full = cut_image(&img, None, 0, 0, w.min(h), Dihedral::IDENTITY);
        if w == h {
            img.diffuse = full.diffuse;
            img.specular = full.specular;
            img.g_block = full.g_block;
        }
        img
    }

    #[test]
    fn inverse_undoes_and_forward_matches_source() {
        for t in Dihedral::all() {
            for (x, y) in [(0, 0), (3, 1), (-1, 2), (4, -1)] {
                let (u, v) = t.forward(x, y, 5);
                assert_eq!(t.source(u, v, 5), (x, y), "{t:?}");
                assert_eq!(t.inverse().forward(u, v, 5), (x, y), "{t:?}");
            }
        }
        // The 8 are distinct.
        let images: Vec<_> = Dihedral::all().map(|t| (t.forward(0, 0, 5), t.forward(1, 0, 5))).collect();
        for i in 0..8 {
            for j in 0..i {
                assert_ne!(images[i], images[j]);
            }
        }
    }

    /// Augmenting a whole square image and then applying the inverse gives back every buffer
    /// exactly — colour blocks with their gradients, G block with normals and gradients, path
    /// weight, pass-through mask, descriptors — and the target too.
    #[test]
    fn augmentation_then_inverse_is_the_identity() {
        let p = 9;
        let img = random_image(p, p, 3, 1);
        let d = img.descriptors.clone().unwrap();
        for t in Dihedral::all() {
            let a = cut_image(&img, Some(&planes(&img, &d, 3)), 0, 0, p, t);
            let ad = a.descriptors.clone().unwrap();
            let back = cut_image(&a, Some(&planes(&a, &ad, 3)), 0, 0, p, t.inverse());
            assert_eq!(back, img, "{t:?}");
            if t != Dihedral::IDENTITY {
                assert_ne!(a, img, "{t:?} moved nothing");
            }
            let target = PreparedTarget {
                width: p,
                height: p,
                diffuse: img.diffuse[..3 * p * p].to_vec(),
                specular: img.g_block[..3 * p * p].to_vec(),
                total: img.specular[..3 * p * p].to_vec(),
            };
            let moved = cut_target(&target, 0, 0, p, t);
            assert_eq!(cut_target(&moved, 0, 0, p, t.inverse()), target);
        }
    }

    /// An augmented patch is the patch of the augmented image: gradients at the patch's first
    /// row and column read the pixels outside it. The identity equals a plain crop.
    #[test]
    fn patch_of_augmented_image() {
        let img = random_image(12, 12, 2, 3);
        let d = img.descriptors.clone().unwrap();
        assert_eq!(cut_image(&img, Some(&planes(&img, &d, 2)), 2, 3, 6, Dihedral::IDENTITY), img.crop(2, 3, 6, 6).unwrap());
        for t in Dihedral::all() {
            let whole = cut_image(&img, Some(&planes(&img, &d, 2)), 0, 0, 12, t);
            // Patch at (2, 3) of side 6 lands at T's image of its corners in the whole image.
            let (u0, v0) = {
                let corners = [(2, 3), (7, 3), (2, 8), (7, 8)].map(|(x, y)| t.forward(x, y, 12));
                (corners.iter().map(|c| c.0).min().unwrap() as usize, corners.iter().map(|c| c.1).min().unwrap() as usize)
            };
            let wd = whole.descriptors.clone().unwrap();
            assert_eq!(
                cut_image(&img, Some(&planes(&img, &d, 2)), 2, 3, 6, t),
                cut_image(&whole, Some(&planes(&whole, &wd, 2)), u0, v0, 6, Dihedral::IDENTITY),
                "{t:?}"
            );
        }
    }

    /// A normal pointing right (+x) in a patch rotated by 90° (transpose then mirror x: the
    /// image turns clockwise) points down (−y); transposing swaps right and down.
    #[test]
    fn normals_rotate_with_the_image() {
        // Clockwise quarter turn: (x, y) → (p−1−y, x).
        let cw = Dihedral(1 | 2);
        assert_eq!(cw.forward(0, 0, 4), (3, 0));
        assert_eq!(cw.forward(1, 0, 4), (3, 1));
        assert_eq!(cw.normal(1.0, 0.0), (0.0, -1.0));
        assert_eq!(cw.normal(0.0, 1.0), (1.0, 0.0));
        assert_eq!(Dihedral(1).normal(1.0, 0.0), (0.0, -1.0));
        assert_eq!(Dihedral(2).normal(0.3, 0.5), (-0.3, 0.5));
        assert_eq!(Dihedral(4).normal(0.3, 0.5), (0.3, -0.5));
        // In a patch, the stored normal planes carry the rotated vector at the moved pixel.
        let img = random_image(6, 6, 1, 9);
        let a = cut_image(&img, None, 0, 0, 6, cw);
        let (x, y) = (1usize, 4usize);
        let (u, v) = cw.forward(x as isize, y as isize, 6);
        let i = y * 6 + x;
        let j = v as usize * 6 + u as usize;
        let (nx, ny) = cw.normal(img.g_block[i], img.g_block[36 + i]);
        assert_eq!((a.g_block[j], a.g_block[36 + j], a.g_block[72 + j]), (nx, ny, img.g_block[72 + i]));
    }
}
