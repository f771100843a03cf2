//! DICOM ultrasound input through dicom-rs (`dicom-object`, `dicom-pixeldata`).
//!
//! Supported transfer syntaxes: implicit and explicit VR little endian, deflated explicit VR
//! little endian, JPEG baseline and extended (lossy 8/12 bit), JPEG lossless, RLE lossless.
//! Others (JPEG 2000, JPEG-LS, MPEG, big endian, ...) get an error naming the syntax.
//!
//! Photometric interpretations: MONOCHROME1/2 (scaled to 0–255 from the bits stored,
//! MONOCHROME1 inverted), RGB (luminance, BT.601), YBR_FULL and YBR_FULL_422 (their Y channel
//! *is* the BT.601 luminance), PALETTE COLOR (indices mapped through the red, green and blue
//! palette tables, then luminance). Multi-frame files: one frame is chosen (from 0).
//!
//! Pixel size: the first region of the Sequence of Ultrasound Regions (0018,6011) whose
//! physical units along x and y (0018,6024/6026) are centimetres (code 3) gives
//! PhysicalDeltaX/Y (0018,602C/602E) ×10 mm; otherwise Pixel Spacing (0028,0030, row spacing
//! then column spacing, mm); otherwise none.

use crate::error::DicError;
use crate::image::{luma, GreyImage, PixelSize};
use dicom_dictionary_std::tags;
use dicom_object::{open_file, DefaultDicomObject, InMemDicomObject};
use dicom_pixeldata::PixelDecoder;
use std::io::Read;
use std::path::Path;

/// Transfer syntaxes decoded here, with their names.
const SUPPORTED: &[(&str, &str)] = &[
    ("1.2.840.10008.1.2", "Implicit VR Little Endian"),
    ("1.2.840.10008.1.2.1", "Explicit VR Little Endian"),
    (
        "1.2.840.10008.1.2.1.99",
        "Deflated Explicit VR Little Endian",
    ),
    ("1.2.840.10008.1.2.4.50", "JPEG Baseline (Process 1)"),
    ("1.2.840.10008.1.2.4.51", "JPEG Extended (Process 2 & 4)"),
    ("1.2.840.10008.1.2.4.57", "JPEG Lossless (Process 14)"),
    ("1.2.840.10008.1.2.4.70", "JPEG Lossless SV1"),
    ("1.2.840.10008.1.2.5", "RLE Lossless"),
];

/// Names of some transfer syntaxes that are not supported, for the error message.
const KNOWN_UNSUPPORTED: &[(&str, &str)] = &[
    ("1.2.840.10008.1.2.2", "Explicit VR Big Endian (retired)"),
    ("1.2.840.10008.1.2.4.80", "JPEG-LS Lossless"),
    ("1.2.840.10008.1.2.4.81", "JPEG-LS Near-Lossless"),
    ("1.2.840.10008.1.2.4.90", "JPEG 2000 Lossless"),
    ("1.2.840.10008.1.2.4.91", "JPEG 2000"),
    ("1.2.840.10008.1.2.4.100", "MPEG2 Main Profile"),
    ("1.2.840.10008.1.2.4.102", "MPEG-4 AVC/H.264"),
    ("1.2.840.10008.1.2.4.201", "HTJ2K Lossless"),
];

/// Whether `path` is a DICOM file: the `.dcm` extension or the `DICM` magic at byte 128.
pub fn is_dicom(path: &Path) -> bool {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dcm") || e.eq_ignore_ascii_case("dicom"))
    {
        return true;
    }
    let mut buf = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut buf))
        .map(|_| &buf[128..132] == b"DICM")
        .unwrap_or(false)
}

/// What the header says about a DICOM image, without decoding the pixels.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DicomInfo {
    pub transfer_syntax: String,
    pub transfer_syntax_name: String,
    pub photometric: String,
    pub width: usize,
    pub height: usize,
    pub frames: usize,
    pub samples_per_pixel: usize,
    pub bits_allocated: usize,
    pub pixel_size: Option<PixelSize>,
}

fn err(path: &Path, message: impl Into<String>) -> DicError {
    DicError::Dicom {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn int_of(obj: &InMemDicomObject, tag: dicom_object::Tag) -> Option<i64> {
    obj.get(tag).and_then(|e| e.to_int::<i64>().ok())
}

/// Reads the header of a DICOM file and checks that its transfer syntax is supported.
pub fn dicom_info(path: &Path) -> Result<DicomInfo, DicError> {
    let obj = open(path)?;
    info_of(path, &obj)
}

/// Opens the file after checking, from the file meta group alone, that its transfer syntax is
/// supported (so an unsupported one gets that error, not a parse error of its data set).
fn open(path: &Path) -> Result<DefaultDicomObject, DicError> {
    let mut f = std::fs::File::open(path)
        .map_err(|e| err(path, format!("cannot open the DICOM file: {e}")))?;
    let mut preamble = [0u8; 128];
    f.read_exact(&mut preamble).map_err(|e| {
        err(
            path,
            format!("not a DICOM file (shorter than its preamble): {e}"),
        )
    })?;
    let data_set_start = crate::dicom_scan::check_meta_lengths(path).map_err(|m| err(path, m))?;
    let meta =
        dicom_object::FileMetaTable::from_reader(std::io::BufReader::new(f)).map_err(|e| {
            err(
                path,
                format!("not a DICOM file (no valid file meta group): {e}"),
            )
        })?;
    let ts = meta.transfer_syntax().trim_end_matches('\0').to_string();
    transfer_syntax_name(path, &ts)?;
    // Every element's declared length checked against the file before dicom-rs allocates it
    // (a deflated data set cannot be walked: its lengths are inside the compressed stream).
    if let (true, Some(start)) = (ts != "1.2.840.10008.1.2.1.99", data_set_start) {
        // From where dicom-rs ends the meta group (its declared group length). Without that
        // start dicom-rs has refused the meta group above.
        crate::dicom_scan::check_lengths(path, start, ts != "1.2.840.10008.1.2")
            .map_err(|m| err(path, m))?;
    }
    open_file(path).map_err(|e| {
        // Issue 32.12: "Could not read data set token" says nothing to a user; a data set
        // that cannot be read to its end is nearly always a file cut short.
        let size = std::fs::metadata(path).map_or(0, |m| m.len());
        err(
            path,
            format!(
                "the DICOM data set cannot be read to its end ({size} bytes): the file is cut short or damaged (the reader said: {e})"
            ),
        )
    })
}

/// Native (uncompressed) transfer syntaxes, whose Pixel Data length follows from the header.
const NATIVE: [&str; 3] = [
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.1",
    "1.2.840.10008.1.2.1.99",
];

/// Checks the header's image size against the limit (before decoding) and, for native pixel
/// data, against the bytes the file holds: a wrong Rows value used to give "Frame #0 is out of
/// range" from the decoder (issue 32.12).
fn check_pixel_data(
    path: &Path,
    obj: &DefaultDicomObject,
    info: &DicomInfo,
) -> Result<(), DicError> {
    femu_mesh::limits::check_image_size(info.width as u64, info.height as u64).map_err(|m| {
        err(
            path,
            format!("Rows (0028,0010) and Columns (0028,0011) say {m}"),
        )
    })?;
    if !NATIVE.contains(&info.transfer_syntax.as_str()) {
        return Ok(());
    }
    let Some(held) = obj
        .element(tags::PIXEL_DATA)
        .ok()
        .and_then(|e| e.value().primitive())
        .map(|p| p.calculate_byte_len() as u64)
    else {
        return Err(err(path, "no Pixel Data (7FE0,0010)"));
    };
    // YBR_FULL_422 stores two samples per pixel (Y for each, Cb and Cr shared by two).
    let samples = match (info.photometric.as_str(), info.samples_per_pixel) {
        ("YBR_FULL_422", 3) => 2,
        (_, s) => s as u64,
    };
    let needed = (info.width as u64)
        .saturating_mul(info.height as u64)
        .saturating_mul(samples)
        .saturating_mul(info.bits_allocated as u64)
        .saturating_mul(info.frames as u64)
        .div_ceil(8);
    if held < needed {
        return Err(err(
            path,
            format!(
                "the header says {} frame(s) of {} rows x {} columns x {} sample(s) of {} bits, {needed} bytes, but the Pixel Data holds {held}: Rows (0028,0010), Columns (0028,0011), Samples per Pixel, Bits Allocated or Number of Frames is wrong, or the file is cut short",
                info.frames, info.height, info.width, info.samples_per_pixel, info.bits_allocated
            ),
        ));
    }
    Ok(())
}

/// The name of a supported transfer syntax, or the error naming an unsupported one.
fn transfer_syntax_name(path: &Path, ts: &str) -> Result<String, DicError> {
    match SUPPORTED.iter().find(|(u, _)| *u == ts) {
        Some((_, n)) => Ok(n.to_string()),
        None => {
            let known = KNOWN_UNSUPPORTED
                .iter()
                .find(|(u, _)| *u == ts)
                .map(|(_, n)| format!(" ({n})"))
                .unwrap_or_default();
            let list: Vec<&str> = SUPPORTED.iter().map(|(_, n)| *n).collect();
            Err(err(
                path,
                format!(
                    "transfer syntax {ts}{known} is not supported; supported: {}",
                    list.join(", ")
                ),
            ))
        }
    }
}

fn info_of(path: &Path, obj: &DefaultDicomObject) -> Result<DicomInfo, DicError> {
    let ts = obj.meta().transfer_syntax().to_string();
    let name = transfer_syntax_name(path, &ts)?;
    let photometric = obj
        .get(tags::PHOTOMETRIC_INTERPRETATION)
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim().trim_end_matches('\0').to_string())
        .ok_or_else(|| err(path, "no Photometric Interpretation (0028,0004)"))?;
    let width = int_of(obj, tags::COLUMNS).ok_or_else(|| err(path, "no Columns (0028,0011)"))?;
    let height = int_of(obj, tags::ROWS).ok_or_else(|| err(path, "no Rows (0028,0010)"))?;
    let frames = obj
        .get(tags::NUMBER_OF_FRAMES)
        .and_then(|e| e.to_str().ok())
        .and_then(|s| s.trim().trim_end_matches('\0').parse::<i64>().ok())
        .unwrap_or(1);
    Ok(DicomInfo {
        transfer_syntax: ts,
        transfer_syntax_name: name,
        photometric,
        width: width as usize,
        height: height as usize,
        frames: frames.max(1) as usize,
        samples_per_pixel: int_of(obj, tags::SAMPLES_PER_PIXEL).unwrap_or(1) as usize,
        bits_allocated: int_of(obj, tags::BITS_ALLOCATED).unwrap_or(8) as usize,
        pixel_size: pixel_size(obj),
    })
}

/// The pixel size from the ultrasound regions or Pixel Spacing (see the module documentation).
fn pixel_size(obj: &InMemDicomObject) -> Option<PixelSize> {
    if let Some(items) = obj
        .get(tags::SEQUENCE_OF_ULTRASOUND_REGIONS)
        .and_then(|e| e.items())
    {
        for region in items {
            let ux = int_of(region, tags::PHYSICAL_UNITS_X_DIRECTION);
            let uy = int_of(region, tags::PHYSICAL_UNITS_Y_DIRECTION);
            let dx = region
                .get(tags::PHYSICAL_DELTA_X)
                .and_then(|e| e.to_float64().ok());
            let dy = region
                .get(tags::PHYSICAL_DELTA_Y)
                .and_then(|e| e.to_float64().ok());
            if let (Some(3), Some(3), Some(dx), Some(dy)) = (ux, uy, dx, dy) {
                if dx.abs() > 0.0 && dy.abs() > 0.0 && dx.is_finite() && dy.is_finite() {
                    return Some(PixelSize {
                        dx_mm: 10.0 * dx.abs(),
                        dy_mm: 10.0 * dy.abs(),
                        source: "SequenceOfUltrasoundRegions",
                    });
                }
            }
        }
    }
    let ps = obj
        .get(tags::PIXEL_SPACING)
        .and_then(|e| e.to_multi_float64().ok())?;
    if ps.len() == 2 && ps.iter().all(|v| *v > 0.0 && v.is_finite()) {
        return Some(PixelSize {
            dx_mm: ps[1],
            dy_mm: ps[0],
            source: "PixelSpacing",
        });
    }
    None
}

/// Expands a segmented palette (PS3.3 C.7.9.2): discrete segments `0, n, v1..vn`, linear
/// segments `1, n, y` (from the last value to `y` in `n` steps) and indirect segments
/// `2, count, offset_lo, offset_hi` (replay `count` segments from word `offset`).
fn expand_segmented(words: &[u16]) -> Result<Vec<f64>, String> {
    fn segment(words: &[u16], i: usize, out: &mut Vec<f64>, depth: usize) -> Result<usize, String> {
        let at = |k: usize| {
            words.get(k).copied().ok_or_else(|| {
                format!(
                    "segment at word {i} runs past the end ({} words)",
                    words.len()
                )
            })
        };
        match at(i)? {
            0 => {
                let n = at(i + 1)? as usize;
                for k in 0..n {
                    out.push(at(i + 2 + k)? as f64);
                }
                Ok(i + 2 + n)
            }
            1 => {
                let n = at(i + 1)? as usize;
                let y1 = at(i + 2)? as f64;
                let y0 = *out
                    .last()
                    .ok_or_else(|| format!("linear segment at word {i} has no start value"))?;
                for k in 1..=n {
                    out.push(y0 + (y1 - y0) * k as f64 / n as f64);
                }
                Ok(i + 3)
            }
            2 => {
                if depth > 0 {
                    return Err(format!("nested indirect segment at word {i}"));
                }
                let count = at(i + 1)? as usize;
                let mut k = at(i + 2)? as usize | ((at(i + 3)? as usize) << 16);
                for _ in 0..count {
                    k = segment(words, k, out, depth + 1)?;
                }
                Ok(i + 4)
            }
            t => Err(format!("unknown segment type {t} at word {i}")),
        }
    }
    let mut out = Vec::new();
    let mut i = 0;
    while i < words.len() {
        i = segment(words, i, &mut out, 0)?;
    }
    Ok(out)
}

/// One palette table: `(entries, first mapped value, values scaled to 0–255)`, from the
/// plain palette data or the segmented one.
fn palette(
    path: &Path,
    obj: &InMemDicomObject,
    desc: dicom_object::Tag,
    data: dicom_object::Tag,
    segmented: dicom_object::Tag,
    colour: &str,
) -> Result<(usize, i64, Vec<f64>), DicError> {
    let d: Vec<i64> = obj
        .get(desc)
        .and_then(|e| e.to_multi_int::<i64>().ok())
        .ok_or_else(|| {
            err(
                path,
                format!("PALETTE COLOR without a {colour} palette descriptor"),
            )
        })?;
    if d.len() != 3 {
        return Err(err(
            path,
            format!("{colour} palette descriptor has {} values, not 3", d.len()),
        ));
    }
    let entries = if d[0] <= 0 { 65536 } else { d[0] as usize };
    let bits = d[2];
    let scale = |w: u16| {
        if bits == 16 {
            w as f64 / 257.0
        } else {
            w as f64
        }
    };
    let values: Vec<f64> = if let Some(el) = obj.get(data) {
        let bytes = el
            .to_bytes()
            .map_err(|e| err(path, format!("{colour} palette data: {e}")))?;
        let words: Vec<u16> = bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        if bits == 16 || bytes.len() >= 2 * entries {
            // One entry per 16-bit word (8-bit entries in the low byte, or in the high byte
            // when some word exceeds 255).
            let high = bits != 16 && words.iter().take(entries).any(|&w| w > 255);
            words
                .iter()
                .take(entries)
                .map(|&w| if high { (w >> 8) as f64 } else { scale(w) })
                .collect()
        } else {
            bytes.iter().take(entries).map(|&b| b as f64).collect()
        }
    } else if let Some(el) = obj.get(segmented) {
        let bytes = el
            .to_bytes()
            .map_err(|e| err(path, format!("segmented {colour} palette data: {e}")))?;
        let words: Vec<u16> = bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        expand_segmented(&words)
            .map_err(|m| err(path, format!("segmented {colour} palette: {m}")))?
            .into_iter()
            .map(|v| if bits == 16 { v / 257.0 } else { v })
            .collect()
    } else {
        return Err(err(
            path,
            format!("PALETTE COLOR without {colour} palette data"),
        ));
    };
    if values.len() < entries {
        return Err(err(
            path,
            format!(
                "{colour} palette data holds {} entries, the descriptor says {entries}",
                values.len()
            ),
        ));
    }
    Ok((entries, d[1], values))
}

/// Reads frame `frame` (from 0) of a DICOM file as grey levels on a 0–255 scale, with the
/// pixel size of its header.
pub fn read_dicom(path: &Path, frame: usize) -> Result<GreyImage, DicError> {
    let obj = open(path)?;
    let info = info_of(path, &obj)?;
    check_pixel_data(path, &obj, &info)?;
    if frame >= info.frames {
        return Err(DicError::Frame {
            path: path.to_path_buf(),
            frame,
            frames: info.frames,
        });
    }
    let decoded = obj.decode_pixel_data_frame(frame as u32).map_err(|e| {
        err(
            path,
            format!(
                "cannot decode the pixel data ({}): {e}",
                info.transfer_syntax_name
            ),
        )
    })?;
    let (w, h) = (decoded.columns() as usize, decoded.rows() as usize);
    let spp = decoded.samples_per_pixel() as usize;
    let bits = decoded.bits_allocated() as usize;
    let stored = decoded.bits_stored() as usize;
    let raw = decoded
        .frame_data(0)
        .map_err(|e| err(path, format!("frame {frame}: {e}")))?;
    let n = w * h;
    let samples: Vec<f64> = match bits {
        8 => raw.iter().map(|&b| b as f64).collect(),
        16 => {
            let signed =
                decoded.pixel_representation() == dicom_pixeldata::PixelRepresentation::Signed;
            raw.chunks_exact(2)
                .map(|c| {
                    let v = u16::from_le_bytes([c[0], c[1]]);
                    if signed {
                        v as i16 as f64
                    } else {
                        v as f64
                    }
                })
                .collect()
        }
        other => {
            return Err(err(
                path,
                format!("{other} bits allocated per sample is not supported (8 or 16)"),
            ))
        }
    };
    let photometric = decoded.photometric_interpretation().to_string();
    let planar = decoded.planar_configuration() != dicom_pixeldata::PlanarConfiguration::Standard;
    let need = if photometric == "YBR_FULL_422" && spp == 3 {
        2 * n
    } else {
        spp * n
    };
    if samples.len() < need {
        return Err(err(
            path,
            format!(
                "frame {frame} holds {} samples, {w} x {h} x {spp} expected",
                samples.len()
            ),
        ));
    }
    let scale = 255.0 / ((1u64 << stored.clamp(1, 16)) - 1) as f64;
    let data: Vec<f64> = match (photometric.as_str(), spp) {
        ("MONOCHROME2", 1) => samples.iter().take(n).map(|v| v * scale).collect(),
        ("MONOCHROME1", 1) => samples.iter().take(n).map(|v| 255.0 - v * scale).collect(),
        ("PALETTE COLOR", 1) => {
            let r = palette(
                path,
                &obj,
                tags::RED_PALETTE_COLOR_LOOKUP_TABLE_DESCRIPTOR,
                tags::RED_PALETTE_COLOR_LOOKUP_TABLE_DATA,
                tags::SEGMENTED_RED_PALETTE_COLOR_LOOKUP_TABLE_DATA,
                "red",
            )?;
            let g = palette(
                path,
                &obj,
                tags::GREEN_PALETTE_COLOR_LOOKUP_TABLE_DESCRIPTOR,
                tags::GREEN_PALETTE_COLOR_LOOKUP_TABLE_DATA,
                tags::SEGMENTED_GREEN_PALETTE_COLOR_LOOKUP_TABLE_DATA,
                "green",
            )?;
            let b = palette(
                path,
                &obj,
                tags::BLUE_PALETTE_COLOR_LOOKUP_TABLE_DESCRIPTOR,
                tags::BLUE_PALETTE_COLOR_LOOKUP_TABLE_DATA,
                tags::SEGMENTED_BLUE_PALETTE_COLOR_LOOKUP_TABLE_DATA,
                "blue",
            )?;
            let look = |t: &(usize, i64, Vec<f64>), v: f64| {
                let k = (v as i64 - t.1).clamp(0, t.0 as i64 - 1) as usize;
                t.2[k]
            };
            samples
                .iter()
                .take(n)
                .map(|&v| luma(look(&r, v), look(&g, v), look(&b, v)))
                .collect()
        }
        ("RGB", 3) => (0..n)
            .map(|k| {
                let (r, g, b) = if planar {
                    (samples[k], samples[n + k], samples[2 * n + k])
                } else {
                    (samples[3 * k], samples[3 * k + 1], samples[3 * k + 2])
                };
                luma(r, g, b) * scale
            })
            .collect(),
        ("YBR_FULL", 3) => (0..n)
            .map(|k| if planar { samples[k] } else { samples[3 * k] } * scale)
            .collect(),
        // Native 4:2:2: Y1 Y2 Cb Cr for each pair of pixels.
        ("YBR_FULL_422", 3) => (0..n)
            .map(|k| samples[4 * (k / 2) + (k % 2)] * scale)
            .collect(),
        (pi, s) => {
            return Err(err(
                path,
                format!(
                    "photometric interpretation {pi} with {s} sample(s) per pixel is not supported"
                ),
            ))
        }
    };
    let mut img = GreyImage::new(w, h, data).map_err(|e| err(path, e.to_string()))?;
    img.pixel_size = info.pixel_size;
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segmented_palette_expands() {
        // discrete [10, 20], linear to 50 in 3 steps, indirect replay of the first segment.
        let words = [0, 2, 10, 20, 1, 3, 50, 2, 1, 0, 0];
        let v = expand_segmented(&words).unwrap();
        assert_eq!(v, vec![10.0, 20.0, 30.0, 40.0, 50.0, 10.0, 20.0]);
        assert!(expand_segmented(&[1, 2, 5]).is_err());
        assert!(expand_segmented(&[0, 5, 1]).is_err());
    }
}
