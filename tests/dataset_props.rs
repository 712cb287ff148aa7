//! Property tests of the `.p2qs` sample format and of candidate labelling: random samples
//! round-trip exactly; every single flipped byte and every truncation is detected (never
//! a panic); arbitrary bytes never panic; labels agree with a brute-force permutation check.

#[path = "common/dataset.rs"]
mod common_dataset;

use point2quad::pipeline::dataset::{encode_sample, label_candidates, read_sample};
use proptest::prelude::*;

/// Brute force: the candidate is some permutation of a ground-truth face.
fn is_face(c: [u32; 4], gt: &[[u32; 4]]) -> bool {
    let mut perms = Vec::new();
    for a in 0..4 {
        for b in 0..4 {
            for c2 in 0..4 {
                for d in 0..4 {
                    let p = [a, b, c2, d];
                    if (0..4).all(|i| (0..i).all(|j| p[i] != p[j])) {
                        perms.push(p);
                    }
                }
            }
        }
    }
    // Distinct vertices only: a face has 4 distinct corners.
    gt.iter().any(|f| perms.iter().any(|p| (0..4).all(|i| c[p[i]] == f[i])))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn samples_roundtrip_exactly(s in common_dataset::sample(40, 30)) {
        let bytes = encode_sample(&s).unwrap();
        let back = read_sample(&bytes, "<memory>").unwrap();
        // Floats compared bit for bit (PartialEq alone would equate −0.0 and 0.0).
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
        prop_assert_eq!(bits(back.points.as_flattened()), bits(s.points.as_flattened()));
        prop_assert_eq!(bits(&back.features), bits(&s.features));
        prop_assert_eq!(back, s);
    }

    #[test]
    fn any_flipped_byte_is_detected(s in common_dataset::sample(20, 10), pos in any::<prop::sample::Index>(), x in 1u8..=255) {
        let mut bytes = encode_sample(&s).unwrap();
        let i = pos.index(bytes.len());
        bytes[i] ^= x;
        prop_assert!(read_sample(&bytes, "<memory>").is_err(), "flip at {} of {} not detected", i, bytes.len());
    }

    #[test]
    fn any_truncation_is_detected(s in common_dataset::sample(20, 10), cut in any::<prop::sample::Index>()) {
        let bytes = encode_sample(&s).unwrap();
        let n = cut.index(bytes.len());
        let e = read_sample(&bytes[..n], "<memory>").unwrap_err().to_string();
        prop_assert!(e.contains("truncated") || e.contains("magic"), "{}", e);
    }

    #[test]
    fn arbitrary_bytes_never_panic(mut bytes in prop::collection::vec(any::<u8>(), 0..200), keep_header in any::<bool>()) {
        if keep_header && bytes.len() >= 8 {
            bytes[..4].copy_from_slice(b"P2QS");
            bytes[4..8].copy_from_slice(&1u32.to_le_bytes());
        }
        let _ = read_sample(&bytes, "<memory>");
    }

    #[test]
    fn labels_match_brute_force(
        gt in prop::collection::vec([0u32..8, 0u32..8, 0u32..8, 0u32..8], 0..6),
        cands in prop::collection::vec([0u32..8, 0u32..8, 0u32..8, 0u32..8], 0..30),
    ) {
        // Ground-truth faces have distinct corners.
        let gt: Vec<[u32; 4]> = gt.into_iter().filter(|f| (0..4).all(|i| (0..i).all(|j| f[i] != f[j]))).collect();
        // Include some true faces in shuffled order so positives occur.
        let mut cands = cands;
        for (k, f) in gt.iter().enumerate() {
            cands.push([f[(k + 2) % 4], f[(k + 1) % 4], f[k % 4], f[(k + 3) % 4]]);
        }
        let labels = label_candidates(&cands, &gt);
        prop_assert_eq!(labels.len(), cands.len());
        for (c, l) in cands.iter().zip(&labels) {
            prop_assert_eq!(*l == 1, is_face(*c, &gt), "{:?}", c);
        }
    }
}
