//! Fuzz tests of the film crate's safetensors readers, `Descriptors::read_safetensors` and `DescriptorFile` (the
//! per-sample path descriptors of a training shot), fed mutated copies of a descriptor file and
//! arbitrary bytes behind a header length. It must return `Ok` or an error, never panic, hang or
//! allocate beyond the cap (the harness: fuzz_support/mod.rs). The denoiser's weight files have
//! their own test, denoiser/tests/fuzz_weights.rs.

mod fuzz_support;

use fuzz_support::*;
use proptest::prelude::*;
use renderer::film::descriptors::{Descriptors, FIELDS};
use renderer::film::{DescriptorFile, Precision};

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

#[test]
fn mutated_descriptor_files_read_or_fail_cleanly() {
    let dir = scratch("descriptors");
    let mut d = Descriptors::new(5, 3, 2);
    d.data.iter_mut().enumerate().for_each(|(i, v)| *v = i as f32 * 0.25);
    let src = dir.join("descriptors_2spp.safetensors");
    d.write_safetensors(&src).unwrap();
    assert_eq!(Descriptors::read_safetensors(&src).unwrap(), d);
    let original = std::fs::read(&src).unwrap();
    let case = dir.join("case.safetensors");

    run_cases("descriptors", 256, 21, Inputs::Mutated, &mutated(1), |tally, (_, edits)| {
        std::fs::write(&case, apply_all(&original, &edits)).unwrap();
        let p = case.clone();
        guarded(tally, label(&src, &edits), move || Descriptors::read_safetensors(&p))
    });

    // Training's in-place reader: a mutated file opens or fails, and every record of an opened
    // one reads or fails, in f32 and in bf16.
    for (precision, seed) in [(Precision::F32, 23), (Precision::Bf16, 24)] {
        let src = dir.join(format!("descriptors_{precision:?}.safetensors"));
        d.write_safetensors_as(&src, precision).unwrap();
        let original = std::fs::read(&src).unwrap();
        run_cases("descriptor file", 128, seed, Inputs::Mutated, &mutated(1), |tally, (_, edits)| {
            std::fs::write(&case, apply_all(&original, &edits)).unwrap();
            let p = case.clone();
            guarded(tally, label(&src, &edits), move || read_every_record(&p))
        });
    }

    // A header of arbitrary text under a length that may or may not match it.
    let header = prop_oneof![prop::collection::vec(any::<u8>(), 0..512), token_soup(SAFETENSORS_TOKENS, 48),];
    let input = (header, any::<bool>(), any::<u64>(), prop::collection::vec(any::<u8>(), 0..256));
    run_cases("descriptors (arbitrary)", 128, 22, Inputs::Arbitrary, &input, |tally, (h, honest, len, data)| {
        let mut b = if honest { (h.len() as u64).to_le_bytes().to_vec() } else { len.to_le_bytes().to_vec() };
        b.extend_from_slice(&h);
        b.extend_from_slice(&data);
        std::fs::write(&case, &b).unwrap();
        let p = case.clone();
        guarded(
            tally,
            format!(
                "header {:?} (length {}), {} data bytes",
                String::from_utf8_lossy(&h),
                if honest { h.len() as u64 } else { len },
                data.len()
            ),
            move || Descriptors::read_safetensors(&p),
        )
    });
}

/// Opens a file with `DescriptorFile` and reads every sample of every pixel.
fn read_every_record(p: &std::path::Path) -> Result<(), film::Error> {
    let f = DescriptorFile::open(p)?;
    let mut out = vec![0.0; f.spp as usize * FIELDS];
    for i in 0..(f.width * f.height) as usize {
        f.read_prefix(i, f.spp as usize, &mut out)?;
    }
    Ok(())
}

const SAFETENSORS_TOKENS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"descriptors\"",
    "\"dtype\"",
    "\"F32\"",
    "\"F16\"",
    "\"U8\"",
    "\"shape\"",
    "\"data_offsets\"",
    "\"__metadata__\"",
    "{\"format\": \"x\"}",
    "[0, 0]",
    "[1, 2, 3, 37]",
    "[0, 4294967296, 1, 37]",
    "37",
    "0",
    "4",
];
