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
