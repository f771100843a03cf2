//! A walk over the element headers of a DICOM data set, before dicom-rs reads it: every
//! element's declared length must fit in the bytes the file has left.
//!
//! dicom-parser allocates and zero-fills a value's declared length before reading it, so a
//! 300-byte file whose header claims a 4 GB value made `femu dic` allocate and write 4 GB
//! (found by fuzzing, issue 28 item 2: libFuzzer's out-of-memory and 10 s timeouts). The walk
//! reads only headers (8 or 12 bytes each) and skips values with a seek.

use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry, VirtualVr};
use dicom_core::{Tag, VR};
use dicom_dictionary_std::StandardDataDictionary;
use std::io::{BufReader, Read, Seek};
use std::path::Path;

/// An undefined length (a sequence, an item or encapsulated pixel data closed by a delimiter).
const UNDEFINED: u32 = 0xFFFF_FFFF;

/// Value representations with a 2-byte reserved field and a 4-byte length in explicit VR.
const LONG_VRS: [&[u8; 2]; 13] = [
    b"OB", b"OD", b"OF", b"OL", b"OV", b"OW", b"SQ", b"UC", b"UN", b"UR", b"UT", b"SV", b"UV",
];

/// Checks the elements of `path` from byte `start` (132, after the preamble and "DICM": the
/// file meta group, always explicit VR little endian, then the data set, in explicit or implicit
/// VR little endian). `Err` names the first element whose length the file cannot hold.
pub fn check_lengths(path: &Path, start: u64, explicit: bool) -> Result<(), String> {
    walk(path, start, explicit, false)
}

/// [`check_lengths`] over the file meta group only (group 0002, explicit VR little endian,
/// after the 128-byte preamble and "DICM"): dicom-rs allocates its values' declared lengths
/// while reading the group, before the transfer syntax of the rest is known (a 4 GB allocation
/// from a fuzzed meta group, issue 28 item 2, second round).
pub fn check_meta_lengths(path: &Path) -> Result<(), String> {
    walk(path, 132, true, true)
}

/// Walks the element headers from byte `start`; with `meta_only`, stops at the first element
/// outside group 0002.
fn walk(path: &Path, start: u64, explicit: bool, meta_only: bool) -> Result<(), String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let size = file.metadata().map_err(|e| e.to_string())?.len();
    let mut r = BufReader::new(file);
    r.seek(std::io::SeekFrom::Start(start))
        .map_err(|e| e.to_string())?;
    let mut pos = start;
    let mut in_pixels = false;
    loop {
        let mut head = [0u8; 8];
        if size.saturating_sub(pos) < 8 || r.read_exact(&mut head).is_err() {
            return Ok(()); // the end, or a cut the reader reports itself
        }
        pos += 8;
        let u16_at = |k: usize| u16::from_le_bytes([head[k], head[k + 1]]);
        let (group, element) = (u16_at(0), u16_at(2));
        if meta_only && group != 0x0002 {
            return Ok(());
        }
        let (len, sequence) = if group == 0xFFFE {
            // Item and delimiters: an implicit-style header in every transfer syntax.
            if element == 0xE0DD {
                in_pixels = false;
            }
            let len = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
            // An item of a sequence holds elements (walked); a fragment of pixel data not.
            (len, !in_pixels)
        } else if explicit || group == 0x0002 {
            let vr = [head[4], head[5]];
            if LONG_VRS.iter().any(|v| **v == vr) {
                let mut l = [0u8; 4];
                if r.read_exact(&mut l).is_err() {
                    return Ok(());
                }
                pos += 4;
                (u32::from_le_bytes(l), &vr == b"SQ")
            } else {
                (u16_at(6) as u32, false)
            }
        } else {
            let len = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
            (len, is_sequence(Tag(group, element)))
        };
        if len == UNDEFINED {
            if (group, element) == (0x7FE0, 0x0010) {
                in_pixels = true;
            }
            continue; // its content follows: walked as elements or items
        }
        let left = size - pos;
        if len as u64 > left {
            return Err(format!(
                "element ({group:04X},{element:04X}) at byte {} declares {len} bytes, and the file has {left} left: the file is cut short or damaged",
                pos - 8
            ));
        }
        if !sequence {
            r.seek_relative(len as i64).map_err(|e| e.to_string())?;
            pos += len as u64;
        }
    }
}

/// Whether the standard dictionary says `tag` is a sequence (implicit VR has no VR field).
fn is_sequence(tag: Tag) -> bool {
    StandardDataDictionary
        .by_tag(tag)
        .is_some_and(|e| matches!(e.vr(), VirtualVr::Exact(VR::SQ)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An explicit VR little endian data set: Rows (US), then an OB value declaring `ob_len`
    /// bytes and holding 4.
    fn data_set(ob_len: u32) -> Vec<u8> {
        let mut d = vec![0x28, 0x00, 0x10, 0x00, b'U', b'S', 2, 0, 48, 0];
        d.extend_from_slice(&[0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0]);
        d.extend_from_slice(&ob_len.to_le_bytes());
        d.extend_from_slice(&[1, 2, 3, 4]);
        d
    }

    #[test]
    fn a_length_beyond_the_file_is_named_and_a_fitting_one_passes() {
        let dir = std::env::temp_dir().join(format!("femu-dicom-scan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.dcm");
        std::fs::write(&p, data_set(4)).unwrap();
        check_lengths(&p, 0, true).unwrap();
        std::fs::write(&p, data_set(0xFFFF_FFF0)).unwrap();
        let e = check_lengths(&p, 0, true).unwrap_err();
        assert!(e.contains("(7FE0,0010)"), "{e}");
        assert!(e.contains("declares 4294967280 bytes"), "{e}");
        assert!(e.contains("has 4 left"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
