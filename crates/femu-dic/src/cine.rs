//! What a multi-frame DICOM (a cine loop) says about its frames beyond the pixels: when each
//! frame was acquired and which part of the frame is the image.
//!
//! - Frame times: Frame Time Vector (0018,1065: the interval before each frame, ms, the first
//!   0) if present, else Frame Time (0018,1063: one interval, ms) times the frame index;
//!   `None` when neither is given (a loop without a time base).
//! - The ultrasound region: the first region of the Sequence of Ultrasound Regions (0018,6011)
//!   whose spatial format (0018,6012) is 2-D (code 1), else the first region; its bounds
//!   RegionLocationMinX0/MinY0/MaxX1/MaxY1 (0018,6018/601A/601C/601E, inclusive pixels). The
//!   rest of the frame holds the scanner's annotations (text, scales, the probe's marker), which
//!   do not move with the tissue.
//!
//! The header is checked by [`crate::dicom::dicom_info`] first (transfer syntax, lengths), so a
//! damaged file gets the same errors as when its pixels are read.

use crate::dicom::{dicom_info, DicomInfo};
use crate::error::DicError;
use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;
use std::path::Path;

/// The image region of a frame: inclusive pixel bounds (column, row).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Region {
    pub x0: usize,
    pub y0: usize,
    pub x1: usize,
    pub y1: usize,
}

impl Region {
    /// Width and height (px).
    pub fn size(&self) -> (usize, usize) {
        (self.x1 + 1 - self.x0, self.y1 + 1 - self.y0)
    }
}

/// The header of a cine loop.
#[derive(Debug, Clone)]
pub struct CineInfo {
    pub info: DicomInfo,
    /// Acquisition time of each frame from the first (s), when the file gives a time base.
    pub frame_times_s: Option<Vec<f64>>,
    /// Which tag gave the times (`"FrameTimeVector"`, `"FrameTime"`).
    pub times_from: Option<&'static str>,
    /// The ultrasound region's bounds, within the frame.
    pub region: Option<Region>,
}

fn err(path: &Path, message: impl Into<String>) -> DicError {
    DicError::Dicom {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Reads the header of `path` (see the module documentation).
pub fn cine_info(path: &Path) -> Result<CineInfo, DicError> {
    let info = dicom_info(path)?;
    let obj = dicom_object::open_file(path)
        .map_err(|e| err(path, format!("cannot read the DICOM data set: {e}")))?;
    let (frame_times_s, times_from) = frame_times(path, &obj, info.frames)?;
    let region = region(path, &obj, info.width, info.height)?;
    Ok(CineInfo {
        info,
        frame_times_s,
        times_from,
        region,
    })
}

type Times = (Option<Vec<f64>>, Option<&'static str>);

fn frame_times(path: &Path, obj: &InMemDicomObject, frames: usize) -> Result<Times, DicError> {
    if let Some(v) = obj
        .get(tags::FRAME_TIME_VECTOR)
        .and_then(|e| e.to_multi_float64().ok())
    {
        if v.len() != frames {
            return Err(err(
                path,
                format!(
                    "Frame Time Vector (0018,1065) has {} values for {frames} frames",
                    v.len()
                ),
            ));
        }
        if let Some((k, d)) = v
            .iter()
            .enumerate()
            .find(|(k, d)| !d.is_finite() || **d < 0.0 || (*k > 0 && **d == 0.0))
        {
            return Err(err(
                path,
                format!("Frame Time Vector (0018,1065): interval {k} is {d} ms; the intervals after the first must be positive"),
            ));
        }
        let mut t = 0.0;
        let times = v
            .iter()
            .enumerate()
            .map(|(k, d)| {
                if k > 0 {
                    t += d / 1000.0;
                }
                t
            })
            .collect();
        return Ok((Some(times), Some("FrameTimeVector")));
    }
    if let Some(ft) = obj.get(tags::FRAME_TIME).and_then(|e| e.to_float64().ok()) {
        if !(ft > 0.0 && ft.is_finite()) {
            return Err(err(
                path,
                format!("Frame Time (0018,1063) is {ft} ms; it must be positive"),
            ));
        }
        let times = (0..frames).map(|k| k as f64 * ft / 1000.0).collect();
        return Ok((Some(times), Some("FrameTime")));
    }
    Ok((None, None))
}

fn int_of(obj: &InMemDicomObject, tag: dicom_object::Tag) -> Option<i64> {
    obj.get(tag).and_then(|e| e.to_int::<i64>().ok())
}

fn region(
    path: &Path,
    obj: &InMemDicomObject,
    width: usize,
    height: usize,
) -> Result<Option<Region>, DicError> {
    let Some(items) = obj
        .get(tags::SEQUENCE_OF_ULTRASOUND_REGIONS)
        .and_then(|e| e.items())
    else {
        return Ok(None);
    };
    let chosen = items
        .iter()
        .find(|r| int_of(r, tags::REGION_SPATIAL_FORMAT) == Some(1))
        .or_else(|| items.first());
    let Some(r) = chosen else {
        return Ok(None);
    };
    let bounds = [
        tags::REGION_LOCATION_MIN_X0,
        tags::REGION_LOCATION_MIN_Y0,
        tags::REGION_LOCATION_MAX_X1,
        tags::REGION_LOCATION_MAX_Y1,
    ]
    .map(|t| int_of(r, t));
    let [Some(x0), Some(y0), Some(x1), Some(y1)] = bounds else {
        return Ok(None);
    };
    let inside = x0 >= 0 && y0 >= 0 && x0 <= x1 && y0 <= y1;
    if !inside || x1 as usize >= width || y1 as usize >= height {
        return Err(err(
            path,
            format!(
                "the ultrasound region's bounds (0018,6018..601E) x {x0}..{x1}, y {y0}..{y1} do not lie in the {width} x {height} px frame"
            ),
        ));
    }
    Ok(Some(Region {
        x0: x0 as usize,
        y0: y0 as usize,
        x1: x1 as usize,
        y1: y1 as usize,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dicom_core::value::DataSetSequence;
    use dicom_core::{DataElement, PrimitiveValue, VR};

    /// A 3-frame 8 x 6 px file with the given extra elements.
    fn cine(name: &str, extra: Vec<DataElement<InMemDicomObject>>) -> std::path::PathBuf {
        let us = |v: u16| PrimitiveValue::from(v);
        let mut obj = InMemDicomObject::from_element_iter([
            DataElement::new(tags::SOP_CLASS_UID, VR::UI, "1.2.840.10008.5.1.4.1.1.3.1"),
            DataElement::new(tags::SOP_INSTANCE_UID, VR::UI, "1.2.3.4"),
            DataElement::new(tags::SAMPLES_PER_PIXEL, VR::US, us(1)),
            DataElement::new(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2"),
            DataElement::new(tags::NUMBER_OF_FRAMES, VR::IS, PrimitiveValue::from("3")),
            DataElement::new(tags::ROWS, VR::US, us(6)),
            DataElement::new(tags::COLUMNS, VR::US, us(8)),
            DataElement::new(tags::BITS_ALLOCATED, VR::US, us(8)),
            DataElement::new(tags::BITS_STORED, VR::US, us(8)),
            DataElement::new(tags::HIGH_BIT, VR::US, us(7)),
            DataElement::new(tags::PIXEL_REPRESENTATION, VR::US, us(0)),
            DataElement::new(
                tags::PIXEL_DATA,
                VR::OB,
                PrimitiveValue::from(vec![7u8; 144]),
            ),
        ]);
        for e in extra {
            obj.put(e);
        }
        let path =
            std::env::temp_dir().join(format!("femu-cine-{name}-{}.dcm", std::process::id()));
        obj.with_meta(
            dicom_object::FileMetaTableBuilder::new().transfer_syntax("1.2.840.10008.1.2.1"),
        )
        .unwrap()
        .write_to_file(&path)
        .unwrap();
        path
    }

    #[test]
    fn frame_times_and_the_region_are_read_and_checked() {
        // Frame Time Vector wins over Frame Time; the first interval is 0.
        let p = cine(
            "vector",
            vec![
                DataElement::new(tags::FRAME_TIME, VR::DS, PrimitiveValue::from("40")),
                DataElement::new(
                    tags::FRAME_TIME_VECTOR,
                    VR::DS,
                    PrimitiveValue::from("0\\33.5\\66.5"),
                ),
            ],
        );
        let c = cine_info(&p).unwrap();
        assert_eq!(c.times_from, Some("FrameTimeVector"));
        let t = c.frame_times_s.unwrap();
        assert!(
            (t[1] - 0.0335).abs() < 1e-12 && (t[2] - 0.1).abs() < 1e-12,
            "{t:?}"
        );
        assert_eq!(c.region, None);
        // Frame Time alone; a 2-D region chosen over the first (a Doppler strip, format 3).
        let region = |format: u16, x0: u32, x1: u32| {
            InMemDicomObject::from_element_iter([
                DataElement::new(
                    tags::REGION_SPATIAL_FORMAT,
                    VR::US,
                    PrimitiveValue::from(format),
                ),
                DataElement::new(
                    tags::REGION_LOCATION_MIN_X0,
                    VR::UL,
                    PrimitiveValue::from(x0),
                ),
                DataElement::new(
                    tags::REGION_LOCATION_MIN_Y0,
                    VR::UL,
                    PrimitiveValue::from(1u32),
                ),
                DataElement::new(
                    tags::REGION_LOCATION_MAX_X1,
                    VR::UL,
                    PrimitiveValue::from(x1),
                ),
                DataElement::new(
                    tags::REGION_LOCATION_MAX_Y1,
                    VR::UL,
                    PrimitiveValue::from(4u32),
                ),
            ])
        };
        let p = cine(
            "time",
            vec![
                DataElement::new(tags::FRAME_TIME, VR::DS, PrimitiveValue::from("40")),
                DataElement::new(
                    tags::SEQUENCE_OF_ULTRASOUND_REGIONS,
                    VR::SQ,
                    DataSetSequence::from(vec![region(3, 0, 7), region(1, 2, 6)]),
                ),
            ],
        );
        let c = cine_info(&p).unwrap();
        assert_eq!(c.times_from, Some("FrameTime"));
        assert_eq!(c.frame_times_s.unwrap(), vec![0.0, 0.04, 0.08]);
        let r = c.region.unwrap();
        assert_eq!((r.x0, r.y0, r.x1, r.y1, r.size()), (2, 1, 6, 4, (5, 4)));
        // Errors: a vector of the wrong length, a region outside the frame; no times at all.
        let p = cine(
            "short",
            vec![DataElement::new(
                tags::FRAME_TIME_VECTOR,
                VR::DS,
                PrimitiveValue::from("0\\33"),
            )],
        );
        let e = cine_info(&p).unwrap_err().to_string();
        assert!(e.contains("2 values for 3 frames"), "{e}");
        let p = cine(
            "outside",
            vec![DataElement::new(
                tags::SEQUENCE_OF_ULTRASOUND_REGIONS,
                VR::SQ,
                DataSetSequence::from(vec![region(1, 2, 8)]),
            )],
        );
        let e = cine_info(&p).unwrap_err().to_string();
        assert!(e.contains("do not lie in the 8 x 6 px frame"), "{e}");
        let c = cine_info(&cine("none", vec![])).unwrap();
        assert_eq!((c.frame_times_s, c.times_from), (None, None));
        for name in ["vector", "time", "short", "outside", "none"] {
            let p =
                std::env::temp_dir().join(format!("femu-cine-{name}-{}.dcm", std::process::id()));
            std::fs::remove_file(p).ok();
        }
    }
}
