//! Fuzz tests of the EXR readers: frames and references (`film::exr_io::read_frame`) and
//! textures and environment maps (`scene::image_io::load_image`, through the image crate), fed
//! mutated copies of the shipped EXR files, a frame with every layer, and arbitrary bytes after
//! the EXR magic number. Each must return `Ok` or an error, never panic, hang or allocate
//! beyond the cap (the harness: fuzz_support/mod.rs).

mod fuzz_support;

use exr::prelude::{read, Blocks, Compression, Encoding, LineOrder, ReadChannels, ReadLayers, Vec2, WritableImage};
use fuzz_support::*;
use proptest::prelude::*;
use proptest::sample::Index;
use renderer::film::{exr_io, Frame, PixelBuffer};
use renderer::scene::image_io;
use std::path::{Path, PathBuf};

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

fn exr_files(folder: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(repo().join(folder))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "exr"))
        .collect();
    out.sort();
    assert!(!out.is_empty(), "no EXR files in {folder}");
    out
}

/// A small frame with every layer `write_frame` knows (radiance, diffuse, specular, albedo,
/// normal, depth, with variances), so mutations reach each channel group.
fn full_frame(dir: &Path) -> PathBuf {
    let n = 7 * 5;
    let buf = |c: usize| {
        let mut b = PixelBuffer::new(c, n);
        b.mean.iter_mut().enumerate().for_each(|(i, v)| *v = i as f32 * 0.01);
        b.var.iter_mut().enumerate().for_each(|(i, v)| *v = i as f32 * 0.001);
        b
    };
    let f = Frame {
        width: 7,
        height: 5,
        spp: 4,
        radiance: buf(3),
        diffuse: Some(buf(3)),
        specular: Some(buf(3)),
        albedo: Some(buf(3)),
        normal: Some(buf(3)),
        depth: Some(buf(1)),
        depth_scale: 10.0,
        descriptors: None,
        nonfinite_samples: 0,
    };
    let p = dir.join("full-frame.exr");
    exr_io::write_frame(&f, &p).unwrap();
    p
}

/// `src` rewritten with another compression and block layout: compressed data mostly fails its
/// checksum-free decompression when a byte flips, so uncompressed, RLE and tiled copies let the
/// mutations reach the pixel and offset-table code.
fn reencode(src: &Path, dst: &Path, compression: Compression, tiled: bool) -> PathBuf {
    let mut image =
        read().no_deep_data().largest_resolution_level().all_channels().first_valid_layer().all_attributes().from_file(src).unwrap();
    let blocks = if tiled { Blocks::Tiles(Vec2(4, 4)) } else { Blocks::ScanLines };
    image.layer_data.encoding = Encoding { compression, blocks, line_order: LineOrder::Increasing };
    image.write().to_file(dst).unwrap();
    dst.to_path_buf()
}

/// The small sources in every encoding.
fn variants(src: &Path, dir: &Path) -> Vec<PathBuf> {
    let stem = src.file_stem().unwrap().to_str().unwrap();
    vec![
        src.to_path_buf(),
        reencode(src, &dir.join(format!("{stem}-raw.exr")), Compression::Uncompressed, false),
        reencode(src, &dir.join(format!("{stem}-rle.exr")), Compression::RLE, false),
        reencode(src, &dir.join(format!("{stem}-tiled.exr")), Compression::Uncompressed, true),
    ]
}

fn fuzz(name: &str, cases: u32, salt: u64, sources: Vec<PathBuf>, read: fn(&Path) -> bool) {
    let dir = scratch(name);
    let originals: Vec<Vec<u8>> = sources.iter().map(|s| std::fs::read(s).unwrap()).collect();
    for (s, o) in sources.iter().zip(&originals) {
        let p = dir.join("valid.exr");
        std::fs::write(&p, o).unwrap();
        assert!(read(&p), "the source {} does not read", s.display());
    }
    let case = dir.join("case.exr");
    run_cases(name, cases, salt, Inputs::Mutated, &mutated(sources.len()), |tally, (i, edits)| {
        std::fs::write(&case, apply_all(&originals[i], &edits)).unwrap();
        let p = case.clone();
        guarded(tally, label(&sources[i], &edits), move || if read(&p) { Ok(()) } else { Err(()) })
    });

    // Hostile values written into the header's attributes themselves (the data window, the
    // channel list, compression, tiles, chunk count), which random positions rarely hit.
    // Half of the edits go to the data window, whose size every allocation follows; one or two
    // words, so that both sides can grow at once.
    let edit = (0..sources.len(), any::<bool>(), any::<Index>(), any::<Index>(), 1..=2usize, prop::sample::select(HOSTILE_I32));
    run_cases(
        &format!("{name} (header attributes)"),
        cases,
        salt ^ 0x5A,
        Inputs::Mutated,
        &edit,
        |tally, (i, window, attr, word, words, value)| {
            let mut b = originals[i].clone();
            let attrs = attributes(&b);
            let pick = if window { attrs.iter().position(|(n, _, _)| n == "dataWindow").unwrap() } else { attr.index(attrs.len()) };
            let (attr_name, at, len) = attrs[pick].clone();
            let at = at + 4 * word.index((len / 4).max(1));
            for k in 0..words {
                if at + 4 * k + 4 <= b.len() {
                    b[at + 4 * k..at + 4 * k + 4].copy_from_slice(&value.to_le_bytes());
                }
            }
            std::fs::write(&case, &b).unwrap();
            let p = case.clone();
            guarded(tally, format!("{} with {words}× {value} in {attr_name} at byte {at}", sources[i].display()), move || {
                if read(&p) {
                    Ok(())
                } else {
                    Err(())
                }
            })
        },
    );
    // Arbitrary bytes behind the magic number and a version word, so they reach the header parser.
    let soup = (prop::sample::select(&[2u32, 0x202, 0x402, 0x802, 0x1002][..]), prop::collection::vec(any::<u8>(), 0..2048));
    run_cases(&format!("{name} (arbitrary)"), cases / 2, salt ^ 0xA5, Inputs::Arbitrary, &soup, |tally, (version, bytes)| {
        let mut b = vec![0x76, 0x2f, 0x31, 0x01];
        b.extend_from_slice(&version.to_le_bytes());
        b.extend_from_slice(&bytes);
        std::fs::write(&case, &b).unwrap();
        let p = case.clone();
        guarded(
            tally,
            format!("{name}: version {version:#x}, {} arbitrary bytes", bytes.len()),
            move || if read(&p) { Ok(()) } else { Err(()) },
        )
    });
}

const HOSTILE_I32: &[i32] = &[0, 1, -1, 2, 3, 15, 16, 99_999, 1_000_000, 16_383, 16_384, 65_535, 0x3fff_fffe, i32::MAX, i32::MIN, -99_999];

/// (name, value offset, value length) of each attribute of the first header.
fn attributes(b: &[u8]) -> Vec<(String, usize, usize)> {
    let mut out = Vec::new();
    let mut pos = 8;
    let cstr = |pos: &mut usize| -> Option<String> {
        let end = *pos + b.get(*pos..)?.iter().position(|&c| c == 0)?;
        let s = String::from_utf8_lossy(&b[*pos..end]).into_owned();
        *pos = end + 1;
        Some(s)
    };
    while let Some(name) = cstr(&mut pos) {
        if name.is_empty() {
            break;
        }
        let Some(_kind) = cstr(&mut pos) else { break };
        let Some(size) = b.get(pos..pos + 4).map(|s| i32::from_le_bytes(s.try_into().unwrap()) as usize) else { break };
        out.push((name, pos + 4, size));
        pos += 4 + size;
    }
    assert!(out.iter().any(|(n, _, _)| n == "dataWindow"), "the source has no dataWindow: {out:?}");
    out
}

fn read_frame(p: &Path) -> bool {
    exr_io::read_frame(p).is_ok()
}

fn read_texture(p: &Path) -> bool {
    image_io::load_image(p, Path::new("scene.toml"), "environment.map").is_ok()
}

#[test]
fn mutated_references_and_frames_read_or_fail_cleanly() {
    let dir = scratch("frames_src");
    let mut sources = exr_files("scenes/references");
    sources.extend(variants(&full_frame(&dir), &dir));
    fuzz("frames", 256, 11, sources, read_frame);
}

#[test]
fn mutated_environment_maps_read_or_fail_cleanly() {
    let dir = scratch("textures_src");
    let mut sources = exr_files("scenes/common");
    sources.push(repo().join("scenes/sunlit-ruins/sky.exr"));
    let small = dir.join("small-sky.exr");
    let texels = (0..16 * 8).map(|i| glam::Vec3::new(i as f32, 1.0, 0.5)).collect();
    exr_io::write_rgb(&small, &renderer::texture::Texture { width: 16, height: 8, texels }).unwrap();
    sources.extend(variants(&small, &dir));
    fuzz("textures", 192, 12, sources, read_texture);
}
