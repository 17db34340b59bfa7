use super::*;
use film::Descriptors;

const W: usize = 3;
const H: usize = 2;

/// A frame whose every buffer value is a distinct, hand-checkable function of (pixel, channel).
fn frame(spp: u32) -> Frame {
    let n = W * H;
    let buf = |ch: usize, f: &dyn Fn(usize, usize) -> f32, v: &dyn Fn(usize, usize) -> f32| PixelBuffer {
        channels: ch,
        mean: (0..n * ch).map(|k| f(k / ch, k % ch)).collect(),
        var: (0..n * ch).map(|k| v(k / ch, k % ch)).collect(),
    };
    Frame {
        width: W as u32,
        height: H as u32,
        spp,
        radiance: buf(3, &|i, c| 1.0 + i as f32 + 0.1 * c as f32, &|_, _| 0.0),
        diffuse: Some(buf(3, &|i, c| 0.5 + 0.1 * i as f32 + 0.01 * c as f32, &|i, c| 0.01 * (i + c + 1) as f32)),
        specular: Some(buf(3, &|i, c| 0.5 + 0.9 * i as f32 + 0.09 * c as f32, &|i, _| 0.02 * (i + 1) as f32)),
        albedo: Some(buf(3, &|i, c| 0.1 * (i + c) as f32, &|_, c| 0.001 * c as f32)),
        normal: Some(buf(3, &|i, c| if c == 2 { 1.0 } else { 0.1 * i as f32 }, &|_, _| 0.004)),
        // Pixel 5 escaped (−0.1), so it must normalise to 0, not to a negative depth.
        depth: Some(buf(1, &|i, _| if i == 5 { -0.1 } else { 0.2 * (i + 1) as f32 }, &|i, _| 0.001 * i as f32)),
        depth_scale: 10.0,
        descriptors: None,
        nonfinite_samples: 0,
    }
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-6 * (1.0 + b.abs())
}

#[test]
fn colour_blocks_follow_method_section_2() {
    let f = frame(4);
    let p = prepare(&f).unwrap();
    let n = W * H;
    let k = 3.0 / 4.0; // unbiased → population variance at S = 4
    let (d, a, sp) = (f.diffuse.as_ref().unwrap(), f.albedo.as_ref().unwrap(), f.specular.as_ref().unwrap());
    for i in 0..n {
        for c in 0..3 {
            assert!(close(p.diffuse[c * n + i], d.mean[3 * i + c] / (a.mean[3 * i + c] + ALBEDO_EPS)));
            assert!(close(p.specular[c * n + i], (1.0 + sp.mean[3 * i + c]).ln()));
        }
        let dv = (0..3).map(|c| d.var[3 * i + c] * k).sum::<f32>() / 3.0;
        let a2 = (0..3).map(|c| (a.mean[3 * i + c] + ALBEDO_EPS).powi(2)).sum::<f32>() / 3.0;
        assert!(close(p.diffuse[3 * n + i], dv / a2), "σ²_D at {i}");
        let sv = (0..3).map(|c| sp.var[3 * i + c] * k).sum::<f32>() / 3.0;
        let s2 = (0..3).map(|c| (1.0 + sp.mean[3 * i + c]).powi(2)).sum::<f32>() / 3.0;
        assert!(close(p.specular[3 * n + i], sv / s2), "σ²_P at {i}");
    }
    // Gradients: x planes then y planes, zero in the first column / row.
    let gx0 = |i: usize| p.diffuse[4 * n + i];
    let gy0 = |i: usize| p.diffuse[7 * n + i];
    assert_eq!(gx0(0), 0.0);
    assert_eq!(gx0(3), 0.0);
    assert!(close(gx0(1), p.diffuse[1] - p.diffuse[0]));
    assert!(close(gx0(5), p.diffuse[5] - p.diffuse[4]));
    assert_eq!(gy0(2), 0.0);
    assert!(close(gy0(4), p.diffuse[4] - p.diffuse[1]));
}

#[test]
fn g_block_layout_depth_normalisation_and_escapes() {
    let f = frame(4);
    let p = prepare(&f).unwrap();
    let n = W * H;
    assert_eq!(p.g_block.len(), G_BLOCK * n);
    // N (0..3), σ²_N (3), ∂N (4..10), Z (10), σ²_Z (11), ∂Z (12, 13), A (14..17), σ²_A (17), ∂A.
    assert_eq!(p.g_block[2 * n + 4], 1.0);
    assert!(close(p.g_block[3 * n], 0.004 * 0.75));
    let zmax = 0.2 * 5.0;
    assert!(close(p.g_block[10 * n + 2], 0.6 / zmax));
    assert_eq!(p.g_block[10 * n + 4], 1.0, "the largest depth normalises to 1");
    assert_eq!(p.g_block[10 * n + 5], 0.0, "an escaped path's −0.1 clips to 0");
    assert!(close(p.g_block[11 * n + 3], 0.003 * 0.75 / (zmax * zmax)));
    assert!(close(p.g_block[12 * n + 2], p.g_block[10 * n + 2] - p.g_block[10 * n + 1]), "∂Z/∂x");
    assert!(close(p.g_block[(14 + 1) * n + 2], f.albedo.as_ref().unwrap().mean[3 * 2 + 1]));
    assert!(close(p.g_block[17 * n], (0.0 + 0.001 + 0.002) * 0.75 / 3.0));
    assert!(p.descriptors.is_none() && p.passthrough.is_empty());
}

#[test]
fn missing_buffers_and_bad_descriptors_are_errors() {
    let mut f = frame(2);
    f.albedo = None;
    assert!(matches!(prepare(&f), Err(PrepareError::MissingBuffer("albedo"))));
    let mut f = frame(4);
    f.descriptors = Some(Descriptors::new(W as u32, H as u32, 2));
    assert!(matches!(prepare(&f), Err(PrepareError::DescriptorShape { .. })), "fewer descriptor samples than spp");
    let mut r = frame(4);
    r.diffuse = None;
    assert!(prepare_target(&r).is_err());
}

#[test]
fn descriptors_are_normalised_prefixes_and_mark_passthrough() {
    let mut f = frame(2);
    let mut d = Descriptors::new(W as u32, H as u32, 4);
    for i in 0..W * H {
        for s in 0..4 {
            let o = (i * 4 + s) * FIELDS;
            for c in 0..FIELDS {
                d.data[o + c] = 0.5 + (s * 100 + c) as f32 * 0.01;
            }
            d.data[o + field::BOUNCE_TYPE] = if i == 1 { 0.0 } else { 9.0 };
            d.data[o + field::PATH_WEIGHT] = (s + 1) as f32;
        }
    }
    f.descriptors = Some(d.clone());
    let p = prepare(&f).unwrap();
    let n = W * H;
    let q = p.descriptors.as_ref().unwrap();
    assert_eq!(q.len(), 2 * DESCRIPTOR_CHANNELS * n, "only the first spp samples are used");
    let i = 4;
    for s in 0..2 {
        for c in 0..DESCRIPTOR_CHANNELS {
            let raw = d.data[(i * 4 + s) * FIELDS + c];
            assert!(close(q[(s * DESCRIPTOR_CHANNELS + c) * n + i], normalise_descriptor(c, raw)));
        }
    }
    assert!(close(normalise_descriptor(0, 1.0), (1.0f32 + 1e-6).ln() / 30.0));
    assert!(close(normalise_descriptor(4, 2.0), (2.0f32 + 1e-8).ln() / 10.0));
    assert!(close(normalise_descriptor(26, 9.0), 9.0 / 19.0));
    assert!(close(normalise_descriptor(33, 0.25), 0.5));
    let pw = ((1.0f32 + 1e-6).ln() / 90.0 + (2.0f32 + 1e-6).ln() / 90.0) / 2.0;
    assert!(close(p.path_weight[3], pw));
    assert_eq!(p.passthrough, vec![false, true, false, false, false, false]);
}

#[test]
fn crops_equal_the_cut_of_the_full_image_and_stack() {
    let mut f = frame(2);
    f.descriptors = Some(Descriptors::new(W as u32, H as u32, 2));
    let p = prepare(&f).unwrap();
    let c = p.crop(1, 1, 2, 1).unwrap();
    let n = W * H;
    for plane in 0..G_BLOCK {
        assert_eq!(c.g_block[plane * 2..plane * 2 + 2], p.g_block[plane * n + 4..plane * n + 6]);
    }
    assert_eq!(c.passthrough.len(), 2);
    assert!(p.crop(2, 0, 2, 1).is_err());
    let device = crate::cpu_device();
    let t = PreparedImage::to_tensors(&[&c, &c], &device);
    assert_eq!(t.diffuse.colour.dims(), [2, COLOUR_BLOCK, 1, 2]);
    assert_eq!(t.specular.descriptors.dims(), [2, 2, DESCRIPTOR_CHANNELS, 1, 2]);
    let tgt = prepare_target(&f).unwrap().crop(0, 0, 3, 2).unwrap();
    assert!(close(tgt.specular[0], (1.0f32 - 0.5).ln_1p()));
    assert_eq!(PreparedTarget::to_tensors(&[&tgt], &device).total.dims(), [1, 3, 2, 3]);
}

#[test]
fn non_finite_buffers_give_finite_inputs() {
    let mut f = frame(4);
    f.diffuse.as_mut().unwrap().mean[0] = f32::NAN;
    f.specular.as_mut().unwrap().mean[4] = f32::INFINITY;
    f.depth.as_mut().unwrap().mean[2] = f32::INFINITY;
    f.albedo.as_mut().unwrap().var[1] = f32::NAN;
    let p = prepare(&f).unwrap();
    for v in [&p.diffuse, &p.specular, &p.g_block] {
        assert!(v.iter().all(|x| x.is_finite()));
    }
}

/// `prepare_for_inference` keeps the records (moved and normalised in place) and reads back exactly what
/// `prepare` puts into planes: same blocks, same columns for any pixel list, same crops.
#[test]
fn records_read_like_planes() {
    let mut f = frame(2);
    let mut d = Descriptors::new(W as u32, H as u32, 3);
    for (k, v) in d.data.iter_mut().enumerate() {
        *v = ((k * 7919) % 1000) as f32 * 0.013 - 2.0;
    }
    d.data[5] = f32::INFINITY; // non-finite, yet comparable (NaN ≠ NaN)
    f.descriptors = Some(d);
    let planes = prepare(&f).unwrap();
    let mut g = f.clone();
    let records = prepare_for_inference(&mut g).unwrap();
    assert!(g.descriptors.is_none(), "moved into the prepared image");
    assert!(records.descriptors.is_none() && records.has_descriptors());
    assert_eq!(records.records, f.descriptors.clone().map(NormalisedRecords::new));
    let mut stripped = records.clone();
    stripped.records = None;
    let mut planes_stripped = planes.clone();
    planes_stripped.descriptors = None;
    assert_eq!(stripped, planes_stripped, "blocks, path weight and pass-through agree");
    let all: Vec<usize> = (0..W * H).collect();
    assert_eq!(records.descriptor_columns(&all).as_ref(), planes.descriptors.as_ref());
    let some = [4, 0, 4, 2];
    let cols = records.descriptor_columns(&some).unwrap();
    assert_eq!(Some(cols.clone()), planes.descriptor_columns(&some));
    assert!(cols.iter().all(|v| v.is_finite()));
    assert_eq!(records.crop(1, 0, 2, 2).unwrap(), planes.crop(1, 0, 2, 2).unwrap());
}
