//! A walk over the element headers of a DICOM data set, before dicom-rs reads it: every
//! element's declared length must fit in the bytes the file has left.
//!
//! dicom-parser allocates and zero-fills a value's declared length before reading it, so a
//! 300-byte file whose header claims a 4 GB value made `femu dic` allocate and write 4 GB
//! (found by fuzzing, issue 28 item 2: libFuzzer's out-of-memory and 10 s timeouts). The walk
//! reads only headers (8 or 12 bytes each) and skips values with a seek.
//!
//! The walk mirrors how dicom-rs 0.10.1 reads a file (where it ends the meta group, how it sizes
//! a header, how far it advances after a binary value): a different reading would let a
//! length past the check. When dicom-rs is upgraded, run the `dicom` fuzz target again
//! (`cargo +nightly fuzz run dicom`, the guide's "Reliability" page,
//! docs/guide/src/explanation/reliability.md) before trusting the walk.

use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry, VirtualVr};
use dicom_core::{Tag, VR};
use dicom_dictionary_std::StandardDataDictionary;
use std::io::{BufReader, Read, Seek};
use std::path::Path;

/// An undefined length (a sequence, an item or encapsulated pixel data closed by a delimiter).
const UNDEFINED: u32 = 0xFFFF_FFFF;

/// Value representations with a 2-byte length in explicit VR (PS3.5 7.1.2, Table 7.1-2). Every
/// other VR, and a VR the standard does not know, has 2 reserved bytes and a 4-byte length:
/// dicom-rs reads an unknown VR as UN, so the walk must too (a fuzzed meta group with VR
/// `A9 A9` hid a 2.8 GB length behind what the walk took for a 2-byte one).
const SHORT_VRS: [&[u8; 2]; 21] = [
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN",
    b"SH", b"SL", b"SS", b"ST", b"TM", b"UI", b"UL", b"US",
];

/// Checks the elements of `path` from byte `start` (132, after the preamble and "DICM": the
/// file meta group, always explicit VR little endian, then the data set, in explicit or implicit
/// VR little endian). `Err` names the first element whose length the file cannot hold.
pub fn check_lengths(path: &Path, start: u64, explicit: bool) -> Result<(), String> {
    walk(path, start, explicit, None).map(|_| ())
}

/// [`check_lengths`] over the file meta group only (explicit VR little endian, after the
/// 128-byte preamble and "DICM"): dicom-rs allocates its values' declared lengths while reading
/// the group, before the transfer syntax of the rest is known (a 4 GB allocation from a fuzzed
/// meta group, issue 28 item 2, second round).
///
/// dicom-rs reads elements, of any group, until it has consumed the bytes that File Meta
/// Information Group Length (0002,0000) declares, and skips values whole (it does not descend
/// into sequences); the walk covers the same bytes the same way (third round: a group length
/// of 16 MB in a 323-byte file let dicom-rs read on past an element of group 0000, into one
/// that asked for 2.8 GB).
///
/// Returns the byte where dicom-rs's reading of the group ends, where it starts the data set:
/// the data set must be walked from there, not from the group's elements as the data set's
/// transfer syntax would read them (sixth round: an element of group 0000 inside the declared
/// group, read by the implicit-VR walk with a 4-byte shorter header, put the walk 4 bytes off
/// dicom-rs). `None` when dicom-rs refuses the group by itself.
pub fn check_meta_lengths(path: &Path) -> Result<Option<u64>, String> {
    let mut first = [0u8; 16];
    let Ok(mut file) = std::fs::File::open(path) else {
        return Ok(None); // the reader says why
    };
    if file.seek(std::io::SeekFrom::Start(132)).is_err() || file.read_exact(&mut first).is_err() {
        return Ok(None); // too short: the reader says so
    }
    // dicom-rs wants the tag (0002,0000) and a length of 4, whatever the VR says (a fuzzed
    // `AS` in place of `UL` went through): the header is 8 or 12 bytes by the VR, as for any
    // element, and the group length is the 4-byte value after it.
    if first[..4] != [0x02, 0x00, 0x00, 0x00] {
        return Ok(None); // dicom-rs refuses it by itself, before any value
    }
    let (length, header) = if SHORT_VRS.iter().any(|v| **v == [first[4], first[5]]) {
        (u16::from_le_bytes([first[6], first[7]]) as u32, 8)
    } else {
        (
            u32::from_le_bytes([first[8], first[9], first[10], first[11]]),
            12,
        )
    };
    if length != 4 {
        return Ok(None);
    }
    let v = &first[header..header + 4];
    let group_length = u32::from_le_bytes([v[0], v[1], v[2], v[3]]);
    walk(
        path,
        132 + header as u64 + 4,
        true,
        Some(group_length as u64),
    )
    .map(Some)
}

/// Walks the element headers from byte `start`. With `meta_bytes`, walks the file meta group
/// as dicom-rs reads it: elements until that many bytes are consumed, values skipped whole.
fn walk(path: &Path, start: u64, explicit: bool, meta_bytes: Option<u64>) -> Result<u64, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let size = file.metadata().map_err(|e| e.to_string())?.len();
    let mut r = BufReader::new(file);
    r.seek(std::io::SeekFrom::Start(start))
        .map_err(|e| e.to_string())?;
    let mut pos = start;
    let mut in_pixels = false;
    loop {
        if meta_bytes.is_some_and(|n| pos - start >= n) {
            return Ok(pos);
        }
        let element_start = pos;
        let mut head = [0u8; 8];
        if size.saturating_sub(pos) < 8 || r.read_exact(&mut head).is_err() {
            return Ok(pos); // the end, or a cut the reader reports itself
        }
        pos += 8;
        let u16_at = |k: usize| u16::from_le_bytes([head[k], head[k + 1]]);
        let (group, element) = (u16_at(0), u16_at(2));
        // The VR as dicom-rs reads it (an item or delimiter has none).
        let (len, sequence, vr) = if group == 0xFFFE {
            // Item and delimiters: an implicit-style header in every transfer syntax.
            if element == 0xE0DD {
                in_pixels = false;
            }
            let len = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
            // An item of a sequence holds elements (walked); a fragment of pixel data not.
            (len, !in_pixels && meta_bytes.is_none(), None)
        } else if explicit || meta_bytes.is_some() {
            // (Group 0002 in the data set is read in the data set's syntax by dicom-rs, as
            // any other group: the walk starts after the meta group.)
            let vr = [head[4], head[5]];
            if SHORT_VRS.iter().any(|v| **v == vr) {
                (u16_at(6) as u32, false, Some(vr))
            } else {
                let mut l = [0u8; 4];
                if r.read_exact(&mut l).is_err() {
                    return Ok(pos);
                }
                pos += 4;
                let sequence = &vr == b"SQ" && meta_bytes.is_none();
                (u32::from_le_bytes(l), sequence, Some(vr))
            }
        } else {
            let len = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
            let tag = Tag(group, element);
            (len, is_sequence(tag), dictionary_vr(tag))
        };
        if meta_bytes.is_none() && len != UNDEFINED {
            if let Some((vr, size)) = vr.and_then(|v| value_size(v).map(|s| (v, s))) {
                if len % size != 0 {
                    return Err(format!(
                        "element ({group:04X},{element:04X}) at byte {element_start}: a {} value of {len} bytes, not a multiple of {size}: the file is damaged",
                        String::from_utf8_lossy(&vr)
                    ));
                }
            }
        }
        if len == UNDEFINED {
            if meta_bytes.is_some() {
                return Ok(pos); // dicom-rs refuses an undefined length in the meta group
            }
            if (group, element) == (0x7FE0, 0x0010) {
                in_pixels = true;
            }
            continue; // its content follows: walked as elements or items
        }
        let left = size - pos;
        if len as u64 > left {
            return Err(format!(
                "element ({group:04X},{element:04X}) at byte {element_start} declares {len} bytes, and the file has {left} left: the file is cut short or damaged"
            ));
        }
        if !sequence {
            r.seek_relative(len as i64).map_err(|e| e.to_string())?;
            pos += len as u64;
        }
    }
}

/// The size of one value of a binary VR. dicom-rs reads `len / size` values of such an element
/// but counts `len` bytes, so a length that is not a multiple puts its reader off by the
/// remainder: every header after it is read from the wrong bytes (a fuzzed SL of 2 bytes made
/// it read a 4 GB length out of the next element's value). PS3.5 6.2 forbids such a length.
fn value_size(vr: [u8; 2]) -> Option<u32> {
    match &vr {
        b"US" | b"SS" | b"OW" => Some(2),
        b"UL" | b"SL" | b"FL" | b"AT" | b"OL" | b"OF" => Some(4),
        b"FD" | b"OD" | b"SV" | b"UV" | b"OV" => Some(8),
        _ => None,
    }
}

/// The VR the standard dictionary gives `tag` (implicit VR), when it is one VR (US or SS: 2
/// bytes either way).
fn dictionary_vr(tag: Tag) -> Option<[u8; 2]> {
    match StandardDataDictionary.by_tag(tag)?.vr() {
        VirtualVr::Exact(vr) => Some(vr.to_bytes()),
        VirtualVr::Xs => Some(*b"US"),
        _ => None,
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
        // A binary value whose length is not a multiple of its size (SL of 2 bytes).
        let mut d = vec![0x28, 0x00, 0x02, 0x01, b'S', b'L', 2, 0, 7, 0];
        d.extend_from_slice(&data_set(4));
        std::fs::write(&p, &d).unwrap();
        let e = check_lengths(&p, 0, true).unwrap_err();
        assert!(
            e.contains("(0028,0102) at byte 0: a SL value of 2 bytes, not a multiple of 4"),
            "{e}"
        );
        // An item has no VR: a fragment of 17 478 bytes (length bytes `46 44`, "FD") is not
        // an FD value of the wrong size.
        let mut d = vec![
            0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
        ];
        d.extend_from_slice(&[0xFE, 0xFF, 0x00, 0xE0]);
        d.extend_from_slice(&17_478u32.to_le_bytes());
        d.extend(std::iter::repeat_n(0u8, 17_478));
        d.extend_from_slice(&[0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
        std::fs::write(&p, &d).unwrap();
        check_lengths(&p, 0, true).unwrap();
        // The same in implicit VR: the dictionary's US for High Bit, 3 bytes.
        let mut d = vec![0x28, 0x00, 0x02, 0x01, 3, 0, 0, 0, 7, 0, 0];
        d.extend_from_slice(&[0x28, 0x00, 0x10, 0x00, 2, 0, 0, 0, 48, 0]);
        std::fs::write(&p, &d).unwrap();
        let e = check_lengths(&p, 0, false).unwrap_err();
        assert!(
            e.contains("a US value of 3 bytes, not a multiple of 2"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A file meta group as dicom-rs reads it: preamble, "DICM", group length `group_length`,
    /// then `rest`.
    fn meta_group(group_length: u32, rest: &[u8]) -> Vec<u8> {
        let mut d = vec![0u8; 128];
        d.extend_from_slice(b"DICM");
        d.extend_from_slice(&[0x02, 0x00, 0x00, 0x00, b'U', b'L', 4, 0]);
        d.extend_from_slice(&group_length.to_le_bytes());
        d.extend_from_slice(rest);
        d
    }

    #[test]
    fn the_meta_group_is_walked_to_its_declared_length_with_unknown_vrs_as_un() {
        let dir = std::env::temp_dir().join(format!("femu-dicom-meta-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("m.dcm");
        // The fuzzed file's shape: an element of group 0000 with VR 00 00 (UN to dicom-rs:
        // 2 reserved bytes, a 4-byte length), then (0002,0002) with VR A9 A9 declaring
        // 0xA9A9A9A9 bytes, which dicom-rs reserves before reading.
        let mut rest = vec![0, 0, 0, 0, 0, 0, 0x0B, 0, 2, 0, 0, 0, 0, 1];
        rest.extend_from_slice(&[2, 0, 2, 0, 0xA9, 0xA9, 0xA9, 0xA9, 0xA9, 0xA9, 0xA9, 0xA9]);
        rest.extend_from_slice(&[0xA9; 40]);
        std::fs::write(&p, meta_group(16_777_314, &rest)).unwrap();
        let e = check_meta_lengths(&p).unwrap_err();
        assert!(e.contains("(0002,0002) at byte 158"), "{e}");
        assert!(e.contains("declares 2846468521 bytes"), "{e}");
        // A group whose declared length ends before the damage: dicom-rs stops there too.
        std::fs::write(&p, meta_group(14, &rest)).unwrap();
        check_meta_lengths(&p).unwrap();
        // A sound group: Transfer Syntax UID (UI, 2-byte length), 20 bytes.
        let mut ts = vec![2, 0, 0x10, 0, b'U', b'I', 20, 0];
        ts.extend_from_slice(b"1.2.840.10008.1.2.1\0");
        std::fs::write(&p, meta_group(28, &ts)).unwrap();
        check_meta_lengths(&p).unwrap();
        // The group length under another VR (`AS`, fuzzed): dicom-rs reads it all the same.
        let mut d = meta_group(16_777_314, &rest);
        d[136..138].copy_from_slice(b"AS");
        std::fs::write(&p, d).unwrap();
        let e = check_meta_lengths(&p).unwrap_err();
        assert!(e.contains("(0002,0002) at byte 158"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
