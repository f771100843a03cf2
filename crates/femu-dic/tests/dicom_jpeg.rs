//! JPEG-baseline DICOM (transfer syntax 1.2.840.10008.1.2.4.50) through femu-dic's reader.
//!
//! No such file is among the shared data, so the test makes them: speckle frames (the virtual
//! lab's, as in ultrasound DIC) encoded with `jpeg-encoder` (8-bit grey, and RGB stored as
//! YCbCr 4:2:2 as ultrasound scanners write YBR_FULL_422), wrapped as encapsulated pixel data
//! (a basic offset table, one fragment per frame) with the header of an ultrasound
//! multi-frame image, written to a file and read back with [`read_dicom`]. Each frame read is
//! compared with
//!
//! 1. the same JPEG codestream decoded independently by `zune-jpeg` (another codec than
//!    dicom-rs's `jpeg-decoder`), its Y channel: the reader's luminance of the decoded RGB is
//!    the Y channel up to rounding (BT.601 luma of the YCbCr→RGB transform is Y exactly, so
//!    the chroma and its upsampling cancel) and the two decoders' integer IDCTs may differ by
//!    one level: ±1 grey level asserted (±1 + 1/2 for colour: R, G, B are rounded to integers
//!    before the luminance);
//! 2. the original pixels, within the JPEG quantization error: each DCT coefficient of an
//!    8 x 8 block is rounded to a multiple of its quantization step `q_k`, an error of at most
//!    `q_k/2`; the DCT is orthonormal, so the RMS pixel error of a block is at most
//!    `sqrt(Σ_k (q_k/2)² / 64)`, plus one grey level for the integer DCT and the 8-bit
//!    rounding of the output. The test computes this bound from the quantization table the
//!    encoder uses (quality 90: IJG Annex K tables scaled by 0.2) and asserts the RMS error
//!    under it, and the mean error (bias) under 0.5 level.
//!
//! Also: a file declaring JPEG 2000 is refused with the syntax's UID and name and the file's
//! path in the message.

use dicom_core::value::{DataSetSequence, PixelFragmentSequence};
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use femu_dic::dicom::{dicom_info, read_dicom};
use femu_dic::lab::Speckle;
use femu_dic::{DicError, GreyImage};
use jpeg_encoder::{ColorType, Encoder, SamplingFactor};
use std::path::PathBuf;

#[path = "../../../scripts/guide/measure.rs"]
mod measure;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

const JPEG_BASELINE: &str = "1.2.840.10008.1.2.4.50";
const US_MULTIFRAME: &str = "1.2.840.10008.5.1.4.1.1.3.1";
const QUALITY: u8 = 90;
const W: usize = 160;
const H: usize = 120;
/// PhysicalDeltaX/Y of the ultrasound region, in cm (0.0382653065 cm as in the ALOKA file).
const DELTA_CM: (f64, f64) = (0.0382653065, 0.0262287877);

/// The IJG luminance table (ITU-T T.81 Annex K.1), row-major.
const LUMA_TABLE: [u32; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113,
    92, 49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99,
];

/// The RMS pixel-error bound of the module documentation for `quality` (IJG scaling, as
/// `jpeg-encoder` applies it to its default tables).
fn rms_error_bound(quality: u32) -> f64 {
    let scale = if quality < 50 {
        5000 / quality
    } else {
        200 - 2 * quality
    };
    let sum: f64 = LUMA_TABLE
        .iter()
        .map(|&v| {
            let q = ((v * scale + 50) / 100).clamp(1, 255) as f64;
            (q / 2.0).powi(2)
        })
        .sum();
    (sum / 64.0).sqrt() + 1.0
}

/// Frame `k`: the virtual lab's speckle, a different seed per frame.
fn grey_frame(k: u64) -> Vec<u8> {
    let img = Speckle::new(W, H, 2.0, 7 + k).reference();
    img.data
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect()
}

/// A colour frame from the grey speckle, every channel away from 0 and 255 (so that no
/// decoded channel is clamped and the luminance of the decoded RGB is the decoded Y).
fn rgb_frame(k: u64) -> Vec<u8> {
    grey_frame(k)
        .iter()
        .flat_map(|&g| {
            let g = g as f64;
            [40.0 + 0.6 * g, 30.0 + 0.7 * g, 60.0 + 0.5 * g].map(|c| c.round() as u8)
        })
        .collect()
}

fn luma8(rgb: &[u8]) -> Vec<f64> {
    rgb.chunks_exact(3)
        .map(|c| femu_dic::image::luma(c[0] as f64, c[1] as f64, c[2] as f64))
        .collect()
}

fn encode(pixels: &[u8], colour: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let mut enc = Encoder::new(&mut out, QUALITY);
    let kind = if colour {
        enc.set_sampling_factor(SamplingFactor::R_4_2_2);
        ColorType::Rgb
    } else {
        ColorType::Luma
    };
    enc.encode(pixels, W as u16, H as u16, kind).unwrap();
    out
}

/// The Y channel of a JPEG codestream, decoded by zune-jpeg.
fn zune_y(jpeg: &[u8]) -> Vec<f64> {
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::Luma);
    let mut dec = zune_jpeg::JpegDecoder::new_with_options(jpeg, options);
    let y = dec.decode().unwrap();
    assert_eq!(y.len(), W * H, "zune-jpeg: one Y sample per pixel");
    y.iter().map(|&v| v as f64).collect()
}

/// Writes a JPEG-baseline ultrasound file holding `jpegs` (one per frame) and returns its
/// path. `colour`: YBR_FULL_422, 3 samples; otherwise MONOCHROME2.
fn write_dicom(name: &str, jpegs: &[Vec<u8>], colour: bool, ts: &str) -> PathBuf {
    let mut obj = InMemDicomObject::new_empty();
    let mut put = |tag, vr, value: PrimitiveValue| obj.put(DataElement::new(tag, vr, value));
    put(tags::SOP_CLASS_UID, VR::UI, US_MULTIFRAME.into());
    put(
        tags::SOP_INSTANCE_UID,
        VR::UI,
        "1.2.826.0.1.3680043.2.1143.7".into(),
    );
    put(tags::MODALITY, VR::CS, "US".into());
    put(
        tags::SAMPLES_PER_PIXEL,
        VR::US,
        PrimitiveValue::from(if colour { 3u16 } else { 1u16 }),
    );
    put(
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        if colour {
            "YBR_FULL_422"
        } else {
            "MONOCHROME2"
        }
        .into(),
    );
    if colour {
        put(
            tags::PLANAR_CONFIGURATION,
            VR::US,
            PrimitiveValue::from(0u16),
        );
    }
    put(
        tags::NUMBER_OF_FRAMES,
        VR::IS,
        jpegs.len().to_string().into(),
    );
    put(tags::ROWS, VR::US, PrimitiveValue::from(H as u16));
    put(tags::COLUMNS, VR::US, PrimitiveValue::from(W as u16));
    put(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(8u16));
    put(tags::BITS_STORED, VR::US, PrimitiveValue::from(8u16));
    put(tags::HIGH_BIT, VR::US, PrimitiveValue::from(7u16));
    put(
        tags::PIXEL_REPRESENTATION,
        VR::US,
        PrimitiveValue::from(0u16),
    );
    put(tags::LOSSY_IMAGE_COMPRESSION, VR::CS, "01".into());
    // One ultrasound region in cm (code 3) over the whole image.
    let region = InMemDicomObject::from_element_iter([
        DataElement::new(
            tags::REGION_LOCATION_MIN_X0,
            VR::UL,
            PrimitiveValue::from(0u32),
        ),
        DataElement::new(
            tags::REGION_LOCATION_MIN_Y0,
            VR::UL,
            PrimitiveValue::from(0u32),
        ),
        DataElement::new(
            tags::REGION_LOCATION_MAX_X1,
            VR::UL,
            PrimitiveValue::from(W as u32 - 1),
        ),
        DataElement::new(
            tags::REGION_LOCATION_MAX_Y1,
            VR::UL,
            PrimitiveValue::from(H as u32 - 1),
        ),
        DataElement::new(
            tags::PHYSICAL_UNITS_X_DIRECTION,
            VR::US,
            PrimitiveValue::from(3u16),
        ),
        DataElement::new(
            tags::PHYSICAL_UNITS_Y_DIRECTION,
            VR::US,
            PrimitiveValue::from(3u16),
        ),
        DataElement::new(
            tags::PHYSICAL_DELTA_X,
            VR::FD,
            PrimitiveValue::from(DELTA_CM.0),
        ),
        DataElement::new(
            tags::PHYSICAL_DELTA_Y,
            VR::FD,
            PrimitiveValue::from(DELTA_CM.1),
        ),
    ]);
    obj.put(DataElement::new(
        tags::SEQUENCE_OF_ULTRASOUND_REGIONS,
        VR::SQ,
        DataSetSequence::from(vec![region]),
    ));
    // Encapsulated pixel data (PS3.5 A.4): fragments of even length, one per frame; the basic
    // offset table holds each frame's offset from the first fragment's item tag (8-byte item
    // headers included).
    let fragments: Vec<Vec<u8>> = jpegs
        .iter()
        .map(|j| {
            let mut f = j.clone();
            if f.len() % 2 == 1 {
                f.push(0);
            }
            f
        })
        .collect();
    let mut offsets = Vec::with_capacity(fragments.len());
    let mut at = 0u32;
    for f in &fragments {
        offsets.push(at);
        at += 8 + f.len() as u32;
    }
    obj.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OB,
        PixelFragmentSequence::new(offsets, fragments),
    ));
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(ts)
                .media_storage_sop_class_uid(US_MULTIFRAME),
        )
        .unwrap();
    let path = std::env::temp_dir().join(format!("femu-dic-{name}-{}.dcm", std::process::id()));
    file.write_to_file(&path).unwrap();
    path
}

/// (max |a - b|, RMS of a - b, mean of a - b)
fn diff(a: &[f64], b: &[f64]) -> (f64, f64, f64) {
    assert_eq!(a.len(), b.len());
    let n = a.len() as f64;
    let max = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    let rms = (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n).sqrt();
    let mean = a.iter().zip(b).map(|(x, y)| x - y).sum::<f64>() / n;
    (max, rms, mean)
}

/// Reads frame `frame` of a file of `frames` frames (grey or colour) and checks it against
/// zune-jpeg's decoding and the original pixels.
fn check(name: &str, frames: usize, frame: usize, colour: bool) {
    let originals: Vec<Vec<u8>> = (0..frames as u64)
        .map(|k| if colour { rgb_frame(k) } else { grey_frame(k) })
        .collect();
    let jpegs: Vec<Vec<u8>> = originals.iter().map(|p| encode(p, colour)).collect();
    let path = write_dicom(name, &jpegs, colour, JPEG_BASELINE);
    // The file holds what was meant: encapsulated pixel data, one fragment per frame and an
    // offset table (re-read with dicom-object alone).
    let raw = dicom_object::open_file(&path).unwrap();
    let pixel_data = raw.element(tags::PIXEL_DATA).unwrap();
    let fragments = pixel_data.fragments().expect("encapsulated pixel data");
    assert_eq!(fragments.len(), frames);
    let expected: Vec<u32> = fragments
        .iter()
        .scan(0u32, |at, f| {
            let o = *at;
            *at += 8 + f.len() as u32;
            Some(o)
        })
        .collect();
    assert_eq!(pixel_data.offset_table(), Some(&expected[..]));
    assert_eq!(raw.meta().transfer_syntax(), JPEG_BASELINE);
    let info = dicom_info(&path).unwrap();
    let img: Result<GreyImage, DicError> = read_dicom(&path, frame);
    let past_end = read_dicom(&path, frames);
    std::fs::remove_file(&path).ok();
    let img = img.unwrap();
    assert_eq!(info.transfer_syntax, JPEG_BASELINE);
    assert_eq!(info.transfer_syntax_name, "JPEG Baseline (Process 1)");
    assert_eq!(
        info.photometric,
        if colour {
            "YBR_FULL_422"
        } else {
            "MONOCHROME2"
        }
    );
    assert_eq!((info.width, info.height, info.frames), (W, H, frames));
    assert_eq!((img.width, img.height), (W, H));
    let ps = img
        .pixel_size
        .expect("pixel size from the ultrasound region");
    assert_eq!(ps.source, "SequenceOfUltrasoundRegions");
    assert!((ps.dx_mm - 10.0 * DELTA_CM.0).abs() < 1e-12);
    assert!((ps.dy_mm - 10.0 * DELTA_CM.1).abs() < 1e-12);
    assert!(matches!(past_end, Err(DicError::Frame { .. })));

    let independent = zune_y(&jpegs[frame]);
    let original = if colour {
        luma8(&originals[frame])
    } else {
        originals[frame].iter().map(|&v| v as f64).collect()
    };
    let (dmax, drms, _) = diff(&img.data, &independent);
    let (emax, erms, emean) = diff(&img.data, &original);
    let bound = rms_error_bound(QUALITY as u32);
    eprintln!(
        "{name}: frame {frame} of {frames}: vs zune-jpeg max {dmax:.3} rms {drms:.3}; \
         vs original max {emax:.2} rms {erms:.3} mean {emean:+.3} (rms bound {bound:.2})"
    );
    let decoder_tolerance = if colour { 1.5 } else { 1.0 };
    let label = format!(
        "{} JPEG baseline, frame {frame} of {frames}",
        if colour { "YBR_FULL_422" } else { "8-bit grey" }
    );
    measure::record(
        &format!("{label}: largest difference from zune-jpeg's decoding"),
        dmax,
        &format!("≤ {decoder_tolerance}"),
        "grey levels",
    );
    measure::record(
        &format!("{label}: RMS difference from the original pixels"),
        erms,
        &format!("≤ {bound:.2} (from the quantization table)"),
        "grey levels",
    );
    measure::record(
        &format!("{label}: mean difference from the original pixels"),
        emean,
        "|·| < 0.5",
        "grey levels",
    );
    assert!(
        dmax <= decoder_tolerance + 1e-9,
        "{name}: {dmax} grey levels from zune-jpeg's decoding"
    );
    assert!(erms <= bound, "{name}: RMS error {erms} > {bound}");
    assert!(emean.abs() < 0.5, "{name}: bias {emean}");
    // The frame chosen, not another one: the other frames are far from it.
    for (k, other) in originals.iter().enumerate().filter(|(k, _)| *k != frame) {
        let other = if colour {
            luma8(other)
        } else {
            other.iter().map(|&v| v as f64).collect()
        };
        let (_, orms, _) = diff(&img.data, &other);
        assert!(orms > 5.0 * bound, "{name}: frame {k} read for {frame}");
    }
}

#[test]
fn jpeg_baseline_grey_single_frame() {
    check("jpeg-grey-1", 1, 0, false);
}

#[test]
fn jpeg_baseline_grey_multi_frame_second_frame() {
    check("jpeg-grey-3", 3, 1, false);
}

#[test]
fn jpeg_baseline_ybr_full_422_single_frame() {
    check("jpeg-ybr-1", 1, 0, true);
}

#[test]
fn jpeg_baseline_ybr_full_422_multi_frame_second_frame() {
    check("jpeg-ybr-3", 3, 1, true);
}

/// A complete file (header, encapsulated JPEG 2000 codestream placeholder) declaring JPEG 2000
/// is refused before its pixels are touched, naming the syntax and the file.
#[test]
fn jpeg_2000_is_refused_by_name() {
    let jpegs = vec![encode(&grey_frame(0), false)];
    let path = write_dicom("j2k", &jpegs, false, "1.2.840.10008.1.2.4.91");
    let info = dicom_info(&path);
    let read = GreyImage::open(&path, 0);
    std::fs::remove_file(&path).ok();
    for msg in [info.unwrap_err().to_string(), read.unwrap_err().to_string()] {
        assert!(
            msg.contains("1.2.840.10008.1.2.4.91")
                && msg.contains("JPEG 2000")
                && msg.contains("not supported")
                && msg.contains(&path.display().to_string()),
            "{msg}"
        );
    }
}
