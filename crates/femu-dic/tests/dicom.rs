//! DICOM input on the three ultrasound files of `../shared/data/dicom/` (skipped with a message
//! when the shared data are absent) and on a synthetic file with an unsupported transfer
//! syntax.

use femu_dic::dicom::{dicom_info, read_dicom};
use femu_dic::{DicError, GreyImage};
use std::path::PathBuf;

fn data_dir() -> Option<PathBuf> {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/dicom");
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("SKIPPED: shared data not found at {}", d.display());
        None
    }
}

fn summary(img: &GreyImage) -> (f64, f64, f64) {
    let n = img.data.len() as f64;
    let mean = img.data.iter().sum::<f64>() / n;
    let max = img.data.iter().cloned().fold(f64::MIN, f64::max);
    let std = (img.data.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
    (mean, std, max)
}

#[test]
fn shared_dicom_files_open_with_their_pixel_size() {
    let Some(dir) = data_dir() else { return };
    // Expected: (file, photometric, frames, pixel size in mm from the header). US1_UNCR holds
    // neither ultrasound regions nor Pixel Spacing; the two others hold regions in cm
    // (PhysicalDeltaX/Y 0.0382653065 and 0.0262287877 cm).
    // The grey-level mean and std of frame 0 were computed independently with pydicom 3.0
    // (`apply_color_lut`, then BT.601 luminance on a 0-255 scale).
    let expected = [
        ("US1_UNCR.dcm", "RGB", 1, None, (35.597, 57.072)),
        (
            "gdcm-US-ALOKA-16.dcm",
            "PALETTE COLOR",
            1,
            Some(0.3826530650258064),
            (29.414, 36.103),
        ),
        (
            "OBXXXX1A_2frame.dcm",
            "PALETTE COLOR",
            2,
            Some(0.2622878766196998),
            (11.800, 35.444),
        ),
    ];
    for (name, photometric, frames, size, stats) in expected {
        let path = dir.join(name);
        let info = dicom_info(&path).unwrap();
        let img = read_dicom(&path, 0).unwrap();
        let (mean, std, max) = summary(&img);
        eprintln!("{name}: {info:?}\n   grey mean {mean:.2} std {std:.2} max {max:.1}");
        assert_eq!((img.width, img.height), (info.width, info.height));
        assert!(
            std > 5.0 && max <= 255.0 + 1e-9,
            "{name}: an image, not noise or blank"
        );
        assert!(
            (mean - stats.0).abs() < 2e-3 && (std - stats.1).abs() < 2e-3,
            "{name}: {mean} {std}"
        );
        assert_eq!(info.photometric, photometric);
        assert_eq!(info.frames, frames);
        match (size, img.pixel_size) {
            (None, None) => {}
            (Some(s), Some(p)) => {
                assert!(
                    (p.dx_mm - s).abs() < 1e-12 && (p.dy_mm - s).abs() < 1e-12,
                    "{p:?}"
                );
                assert_eq!(p.source, "SequenceOfUltrasoundRegions");
            }
            (s, p) => panic!("{name}: pixel size {p:?}, expected {s:?}"),
        }
        if frames > 1 {
            // The second frame is another image (the probe moved between frames).
            let second = read_dicom(&path, 1).unwrap();
            let diff = img
                .data
                .iter()
                .zip(&second.data)
                .filter(|(a, b)| a != b)
                .count();
            eprintln!("   frame 1 differs from frame 0 in {diff} pixels");
            assert!(diff > 0);
            let (m1, s1, _) = summary(&second);
            assert!(
                (m1 - 39.822).abs() < 2e-3 && (s1 - 49.784).abs() < 2e-3,
                "frame 1: {m1} {s1}"
            );
        }
        let e = read_dicom(&path, frames).unwrap_err();
        assert!(matches!(e, DicError::Frame { .. }), "{e}");
    }
}

/// A file whose meta group declares JPEG 2000 gets an error naming the transfer syntax.
#[test]
fn unsupported_transfer_syntax_is_a_clear_error() {
    let meta = dicom_object::FileMetaTableBuilder::new()
        .transfer_syntax("1.2.840.10008.1.2.4.91")
        .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.6.1")
        .media_storage_sop_instance_uid("1.2.3.4.5")
        .build()
        .unwrap();
    let mut bytes = vec![0u8; 128];
    bytes.extend_from_slice(b"DICM");
    meta.write(&mut bytes).unwrap();
    let path = std::env::temp_dir().join(format!("femu-dic-j2k-{}.dcm", std::process::id()));
    std::fs::write(&path, &bytes).unwrap();
    let e = GreyImage::open(&path, 0).unwrap_err();
    let msg = e.to_string();
    std::fs::remove_file(&path).ok();
    assert!(
        msg.contains("1.2.840.10008.1.2.4.91")
            && msg.contains("JPEG 2000")
            && msg.contains("not supported"),
        "{msg}"
    );
}
