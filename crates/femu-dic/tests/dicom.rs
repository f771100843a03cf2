//! DICOM input on the three ultrasound files of `../shared/data/dicom/` (skipped with a message
//! when the shared data are absent) and on a synthetic file with an unsupported transfer
//! syntax.

use femu_dic::dicom::{dicom_info, read_dicom};
use femu_dic::{DicError, GreyImage};
use std::path::PathBuf;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;

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
        measure::record(
            &format!(
                "{name}, frame 0: grey-level mean and std against pydicom's, largest difference"
            ),
            (mean - stats.0).abs().max((std - stats.1).abs()),
            "< 2e-3",
            "grey levels",
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
            measure::record(
                &format!("{name}, frame 1: grey-level mean and std against pydicom's, largest difference"),
                (m1 - 39.822).abs().max((s1 - 49.784).abs()),
                "< 2e-3",
                "grey levels",
            );
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

/// A native (explicit VR little endian) MONOCHROME2 8-bit file holding 64 x 48 pixels whose
/// Rows and Columns say `rows`, `columns`, written to a temporary file.
fn native_file(name: &str, rows: u16, columns: u16) -> PathBuf {
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_dictionary_std::tags;
    let (w, h) = (64u16, 48u16);
    let pixels: Vec<u8> = (0..w as usize * h as usize)
        .map(|k| (k * 7 % 251) as u8)
        .collect();
    let obj = dicom_object::InMemDicomObject::from_element_iter([
        DataElement::new(tags::SOP_CLASS_UID, VR::UI, "1.2.840.10008.5.1.4.1.1.6.1"),
        DataElement::new(tags::SOP_INSTANCE_UID, VR::UI, "1.2.3.4.5.6"),
        DataElement::new(tags::SAMPLES_PER_PIXEL, VR::US, PrimitiveValue::from(1u16)),
        DataElement::new(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2"),
        DataElement::new(tags::ROWS, VR::US, PrimitiveValue::from(rows)),
        DataElement::new(tags::COLUMNS, VR::US, PrimitiveValue::from(columns)),
        DataElement::new(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(8u16)),
        DataElement::new(tags::BITS_STORED, VR::US, PrimitiveValue::from(8u16)),
        DataElement::new(tags::HIGH_BIT, VR::US, PrimitiveValue::from(7u16)),
        DataElement::new(
            tags::PIXEL_REPRESENTATION,
            VR::US,
            PrimitiveValue::from(0u16),
        ),
        DataElement::new(tags::PIXEL_DATA, VR::OB, PrimitiveValue::from(pixels)),
    ]);
    let file = obj
        .with_meta(dicom_object::FileMetaTableBuilder::new().transfer_syntax("1.2.840.10008.1.2.1"))
        .unwrap();
    let path = std::env::temp_dir().join(format!("femu-dic-{name}-{}.dcm", std::process::id()));
    file.write_to_file(&path).unwrap();
    path
}

/// Issue 32.12 and 28.4: what is wrong with an image file, in the user's terms and before any
/// large allocation — a wrong Rows value (was "Frame #0 is out of range"), a file cut short (was
/// "Could not read data set token"), a header claiming 10⁹ pixels (DICOM and PNG: refused with
/// the size, the estimate and the limit), a 32-bit float TIFF (was "color type Unknown(32)").
#[test]
fn bad_image_files_are_explained() {
    let good = native_file("good", 48, 64);
    let img = read_dicom(&good, 0).unwrap();
    assert_eq!((img.width, img.height), (64, 48));
    let msg = |p: &PathBuf| GreyImage::open(p, 0).unwrap_err().to_string();
    // Rows 400 for 48 rows of pixels.
    let rows = native_file("rows", 400, 64);
    let e = msg(&rows);
    assert!(
        e.contains("400 rows x 64 columns")
            && e.contains("25600 bytes")
            && e.contains("holds 3072")
            && e.contains("Rows (0028,0010)"),
        "{e}"
    );
    // Cut short inside its pixel data.
    let bytes = std::fs::read(&good).unwrap();
    let cut = std::env::temp_dir().join(format!("femu-dic-cut-{}.dcm", std::process::id()));
    std::fs::write(&cut, &bytes[..bytes.len() - 1000]).unwrap();
    let e = msg(&cut);
    assert!(e.contains("cut short"), "{e}");
    // A header claiming 60 000 x 60 000 pixels.
    let huge = native_file("huge", 60_000, 60_000);
    let e = msg(&huge);
    assert!(
        e.contains("Rows (0028,0010) and Columns (0028,0011) say 60000 x 60000 pixels")
            && e.contains("above the limit"),
        "{e}"
    );
    // A PNG header claiming 40 000 x 25 000 pixels, a few bytes of data: refused at once.
    let png = std::env::temp_dir().join(format!("femu-dic-huge-{}.png", std::process::id()));
    std::fs::write(&png, png_header(40_000, 25_000)).unwrap();
    let t = std::time::Instant::now();
    let e = msg(&png);
    assert!(
        e.contains("40000 x 25000 pixels") && e.contains("above the limit of 50000000"),
        "{e}"
    );
    assert!(t.elapsed().as_secs_f64() < 1.0);
    // A 32-bit float TIFF.
    let tif = std::env::temp_dir().join(format!("femu-dic-float-{}.tif", std::process::id()));
    std::fs::write(&tif, float_tiff(16, 16)).unwrap();
    let e = msg(&tif);
    assert!(
        e.contains("floating-point") && e.contains("16-bit integer"),
        "{e}"
    );
    for p in [good, rows, cut, huge, png, tif] {
        std::fs::remove_file(p).ok();
    }
}

/// A little-endian baseline TIFF of `w` x `h` 32-bit floating-point grey samples (one strip).
fn float_tiff(w: u32, h: u32) -> Vec<u8> {
    let data_at = 8u32;
    let n = w * h;
    let mut out = b"II*\0".to_vec();
    let ifd_at = data_at + 4 * n;
    out.extend(ifd_at.to_le_bytes());
    for k in 0..n {
        out.extend((k as f32 / n as f32).to_le_bytes());
    }
    // (tag, type 3 = SHORT or 4 = LONG, value)
    let entries: [(u16, u16, u32); 10] = [
        (256, 4, w),
        (257, 4, h),
        (258, 3, 32),
        (259, 3, 1),
        (262, 3, 1),
        (273, 4, data_at),
        (277, 3, 1),
        (278, 4, h),
        (279, 4, 4 * n),
        (339, 3, 3),
    ];
    out.extend((entries.len() as u16).to_le_bytes());
    for (tag, kind, value) in entries {
        out.extend(tag.to_le_bytes());
        out.extend(kind.to_le_bytes());
        out.extend(1u32.to_le_bytes());
        out.extend(value.to_le_bytes());
    }
    out.extend(0u32.to_le_bytes());
    out
}

/// The signature and IHDR chunk of an 8-bit grey PNG of `w` x `h`, then an empty IDAT and IEND.
fn png_header(w: u32, h: u32) -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc32(&body).to_be_bytes());
    }
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xffff_ffffu32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &[]);
    chunk(&mut out, b"IEND", &[]);
    out
}
