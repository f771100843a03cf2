//! Label images: integer images whose pixel values name tissues (ITK-SNAP, 3D Slicer and ScanIP
//! segmentations), read from PNG or TIFF (8- or 16-bit grey) or NIfTI-1 (`.nii`, `.nii.gz`, one
//! axial slice), and the table that maps label values to regions, bone and background.
//!
//! Pixel `(i, j)` of a [`LabelImage`] covers `[i sx, (i+1) sx] x [j sy, (j+1) sy]` in the model
//! frame (mm): `i` is the column, `j` counts rows **upwards**. A PNG/TIFF's first row is the top
//! of the picture, so it becomes `j = height - 1`; a NIfTI slice keeps its voxel axes
//! (`i` along the first axis, `j` along the second, the slice along the third).

use crate::GeometryError;
use std::collections::BTreeMap;
use std::path::Path;

/// An integer label image (see the module documentation for the pixel frame).
#[derive(Debug, Clone, PartialEq)]
pub struct LabelImage {
    pub width: usize,
    pub height: usize,
    /// Labels, `labels[j * width + i]`, `j` counting rows upwards.
    pub labels: Vec<u32>,
    /// Pixel size `[sx, sy]` (mm) given by the file (NIfTI `pixdim`), if any.
    pub pixel_size_mm: Option<[f64; 2]>,
}

impl LabelImage {
    /// An image from rows given top row first (as pictures are stored).
    pub fn from_rows_top_down(width: usize, height: usize, rows: &[u32]) -> Self {
        assert_eq!(rows.len(), width * height, "label image size");
        let mut labels = vec![0; width * height];
        for r in 0..height {
            let j = height - 1 - r;
            labels[j * width..(j + 1) * width].copy_from_slice(&rows[r * width..(r + 1) * width]);
        }
        LabelImage {
            width,
            height,
            labels,
            pixel_size_mm: None,
        }
    }

    /// The label of pixel `(i, j)`.
    pub fn get(&self, i: usize, j: usize) -> u32 {
        self.labels[j * self.width + i]
    }

    /// Number of pixels of each label value.
    pub fn histogram(&self) -> BTreeMap<u32, usize> {
        let mut h = BTreeMap::new();
        for &l in &self.labels {
            *h.entry(l).or_insert(0) += 1;
        }
        h
    }
}

/// Reads a label image: PNG or TIFF (8/16-bit grey; an RGB picture whose three channels are
/// equal is accepted), or NIfTI-1 (`.nii`, `.nii.gz`; `slice` is the index along the third
/// axis, required when the volume has more than one slice). The pixel size of a NIfTI file comes
/// from its header (`pixdim`, converted to mm with `xyzt_units`).
pub fn read_label_image(path: &Path, slice: Option<usize>) -> Result<LabelImage, GeometryError> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        read_nifti(path, slice)
    } else {
        if slice.is_some_and(|s| s > 0) {
            return Err(GeometryError::NotALabelImage {
                path: path.to_path_buf(),
                reason: "a slice index is only meaningful for a NIfTI volume".into(),
            });
        }
        read_picture(path)
    }
}

fn read_picture(path: &Path) -> Result<LabelImage, GeometryError> {
    let bad = |reason: String| GeometryError::NotALabelImage {
        path: path.to_path_buf(),
        reason,
    };
    let read_err = |message: String| GeometryError::ImageRead {
        path: path.to_path_buf(),
        message,
    };
    let open = || {
        image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| read_err(e.to_string()))
    };
    // The header's size checked before the pixels are decoded (issue 28.4).
    let (w, h) = open()?
        .into_dimensions()
        .map_err(|e| read_err(e.to_string()))?;
    femu_mesh::limits::check_image_size(w as u64, h as u64).map_err(bad)?;
    let img = open()?.decode().map_err(|e| match e {
        image::ImageError::Unsupported(_) => bad(format!(
            "{e} (label images are 8- or 16-bit integer grey: a floating-point TIFF is not one)"
        )),
        e => read_err(e.to_string()),
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    use image::DynamicImage as D;
    let rows: Vec<u32> = match &img {
        D::ImageLuma8(b) => b.as_raw().iter().map(|&v| v as u32).collect(),
        D::ImageLumaA8(b) => b.as_raw().chunks_exact(2).map(|p| p[0] as u32).collect(),
        D::ImageLuma16(b) => b.as_raw().iter().map(|&v| v as u32).collect(),
        D::ImageLumaA16(b) => b.as_raw().chunks_exact(2).map(|p| p[0] as u32).collect(),
        D::ImageRgb8(_) | D::ImageRgba8(_) => {
            let rgb = img.to_rgb8();
            grey_from_rgb(
                rgb.as_raw()
                    .chunks_exact(3)
                    .map(|p| [p[0], p[1], p[2]].map(u32::from)),
            )
            .map_err(bad)?
        }
        D::ImageRgb16(_) | D::ImageRgba16(_) => {
            let rgb = img.to_rgb16();
            grey_from_rgb(
                rgb.as_raw()
                    .chunks_exact(3)
                    .map(|p| [p[0], p[1], p[2]].map(u32::from)),
            )
            .map_err(bad)?
        }
        other => {
            return Err(bad(format!(
                "pixel type {:?} (expected 8- or 16-bit integer grey values)",
                other.color()
            )))
        }
    };
    if w == 0 || h == 0 {
        return Err(bad("the image is empty".into()));
    }
    Ok(LabelImage::from_rows_top_down(w, h, &rows))
}

/// Grey values from RGB pixels whose three channels are equal.
fn grey_from_rgb(px: impl Iterator<Item = [u32; 3]>) -> Result<Vec<u32>, String> {
    let mut out = Vec::new();
    for (k, [r, g, b]) in px.enumerate() {
        if r != g || g != b {
            return Err(format!(
                "pixel {k} is coloured ({r}, {g}, {b}); a label image has one integer per pixel"
            ));
        }
        out.push(r);
    }
    Ok(out)
}

/// The largest NIfTI volume read, in bytes (5e8 one-byte voxels, 5e8 / 4 floats).
const MAX_VOLUME_BYTES: u64 = 2_000_000_000;

fn read_nifti(path: &Path, slice: Option<usize>) -> Result<LabelImage, GeometryError> {
    use nifti::{NiftiHeader, NiftiObject, NiftiVolume, RandomAccessNiftiVolume, ReaderOptions};
    // The header's size checked before the volume is read (issue 28.4).
    let header = NiftiHeader::from_file(path).map_err(|e| GeometryError::ImageRead {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let d = header.dim;
    let n = (d[0] as usize).clamp(1, 7);
    let slice_px = [d[1], d[2]].map(|v| v.max(1) as u64);
    let voxels = d[1..=n]
        .iter()
        .fold(1u64, |acc, &v| acc.saturating_mul(v.max(1) as u64));
    let too_big = |reason: String| GeometryError::NotALabelImage {
        path: path.to_path_buf(),
        reason,
    };
    // The nifti crate sizes its buffer from these dimensions as they are: a zero or negative
    // one (an i16) becomes a size beyond any memory (found by fuzzing, issue 28 item 2).
    if let Some(bad) = d[1..=n].iter().find(|&&v| v < 1) {
        return Err(too_big(format!(
            "the header's dimensions {:?} hold {bad}: every dimension of a volume is at least 1 (the header is damaged)",
            &d[1..=n]
        )));
    }
    femu_mesh::limits::check_image_size(slice_px[0], slice_px[1]).map_err(too_big)?;
    if voxels > femu_mesh::limits::MAX_VOLUME_VOXELS {
        return Err(too_big(format!(
            "the header's dimensions {:?} make {voxels:.1e} voxels, above the limit of {} (the volume is read whole): cut out the slices you need",
            &d[1..=n],
            femu_mesh::limits::MAX_VOLUME_VOXELS
        )));
    }
    // The nifti crate allocates the header's voxel bytes before reading them: a header that
    // promises more bytes than an uncompressed file holds is cut short (or forged), and no
    // volume above MAX_VOLUME_BYTES is read (a 3.3 GB allocation from a fuzzed header, issue 28
    // item 2, second round).
    // The crate sizes it as `bitpix as usize / 8`: a negative bitpix (an i16) is a size beyond
    // any memory (found by fuzzing, issue 28 item 2).
    if header.bitpix < 8 || header.bitpix % 8 != 0 {
        return Err(too_big(format!(
            "the header's bitpix is {}: a voxel is a whole number of bytes (8, 16, 32, 64 or 128 bits; the header is damaged)",
            header.bitpix
        )));
    }
    let bytes_per_voxel = (header.bitpix / 8) as u64;
    let need = voxels.saturating_mul(bytes_per_voxel);
    if need > MAX_VOLUME_BYTES {
        return Err(too_big(format!(
            "the header's dimensions {:?} of {bytes_per_voxel}-byte voxels make {need:.1e} bytes, above the limit of {MAX_VOLUME_BYTES:.1e} (the volume is read whole): cut out the slices you need",
            &d[1..=n],
        )));
    }
    // A single uncompressed file (.nii) holds its voxels after vox_offset; a .nii.gz's size
    // says nothing, and a .hdr's voxels are in its .img.
    let single = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("nii"));
    if single {
        let size = std::fs::metadata(path).map_or(0, |m| m.len());
        let offset = (header.vox_offset.max(0.0) as u64).max(348);
        if size < offset.saturating_add(need) {
            return Err(too_big(format!(
                "the header's dimensions {:?} of {bytes_per_voxel}-byte voxels need {need} bytes after byte {offset}, and the file has {size} bytes: the file is cut short",
                &d[1..=n],
            )));
        }
    }
    let obj = ReaderOptions::new()
        .read_file(path)
        .map_err(|e| GeometryError::ImageRead {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
    let header = obj.header().clone();
    let vol = obj.volume();
    let dim = vol.dim().to_vec();
    let bad = |reason: String| GeometryError::NotALabelImage {
        path: path.to_path_buf(),
        reason,
    };
    if dim.len() < 2 || dim.len() > 4 || dim.get(3).is_some_and(|&t| t > 1) {
        return Err(bad(format!(
            "volume of dimensions {dim:?}; expected a 2D image or a 3D volume of axial slices"
        )));
    }
    let (nx, ny) = (dim[0] as usize, dim[1] as usize);
    let nz = dim.get(2).map_or(1, |&z| z as usize);
    // The nifti crate reads what the file holds and indexes it unchecked (a panic on a file
    // shorter than its header says: found by fuzzing, issue 28 item 2).
    let need = dim.iter().map(|&v| v as usize).product::<usize>() * vol.data_type().size_of();
    if vol.raw_data().len() < need {
        return Err(bad(format!(
            "the header's dimensions {dim:?} need {need} bytes of voxels and the file holds {}: the file is cut short",
            vol.raw_data().len()
        )));
    }
    let k = match slice {
        Some(k) => k,
        None if nz == 1 => 0,
        None => {
            return Err(bad(format!(
                "the volume has {nz} slices; choose one with a slice index"
            )))
        }
    };
    if k >= nz {
        return Err(GeometryError::NoSuchSlice {
            path: path.to_path_buf(),
            index: k,
            count: nz,
        });
    }
    let mut labels = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let mut c = vec![i as u16, j as u16];
            if dim.len() >= 3 {
                c.push(k as u16);
            }
            if dim.len() == 4 {
                c.push(0);
            }
            let v = vol.get_f64(&c).map_err(|e| GeometryError::ImageRead {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
            if !(v >= 0.0) || v.fract() != 0.0 || v > u32::MAX as f64 {
                return Err(bad(format!(
                    "voxel ({i}, {j}, {k}) holds {v}, not a non-negative integer label"
                )));
            }
            labels.push(v as u32);
        }
    }
    // NIfTI-1 xyzt_units, spatial part: 1 metre, 2 millimetre, 3 micron, 0 unknown (mm assumed).
    let to_mm = match header.xyzt_units & 0x07 {
        1 => 1000.0,
        3 => 1e-3,
        _ => 1.0,
    };
    let (sx, sy) = (
        header.pixdim[1] as f64 * to_mm,
        header.pixdim[2] as f64 * to_mm,
    );
    let pixel_size_mm =
        (sx > 0.0 && sy > 0.0 && sx.is_finite() && sy.is_finite()).then_some([sx, sy]);
    Ok(LabelImage {
        width: nx,
        height: ny,
        labels,
        pixel_size_mm,
    })
}

/// What each label value of an image is: a region (several labels may share one region), the
/// bone (a hole whose edge is fixed) or the background (outside the body).
#[derive(Debug, Clone, PartialEq)]
pub struct LabelSpec {
    /// `(label, region name)`; region names are upper-cased element-set names.
    pub regions: Vec<(u32, String)>,
    /// Labels of the bone (the femur).
    pub bone: Vec<u32>,
    /// Labels of the background (default `[0]`).
    pub background: Vec<u32>,
}

impl LabelSpec {
    /// A spec from a `--map` text (see [`parse_label_map`]), bone and background labels.
    pub fn new(map: &str, bone: &[u32], background: &[u32]) -> Result<Self, GeometryError> {
        let spec = LabelSpec {
            regions: parse_label_map(map)?,
            bone: bone.to_vec(),
            background: background.to_vec(),
        };
        spec.validate()?;
        Ok(spec)
    }

    /// The label map of the shared thigh MRI slice (`thigh_001_slice06_labels.png`): 1 fat,
    /// 2 quadriceps, 3 ischio, 4 gracilis, 5 sartorius, 6 adductor magnus → ISCHIO (it has no
    /// Table 1 value; its posterior, ischio-condylar part is a hamstring and it lies beside
    /// them), 7 femur, 0 outside.
    pub fn thigh_mri() -> Self {
        LabelSpec::new(
            "1=fat,2=quadriceps,3=ischio,4=gracilis,5=sartorius,6=ischio",
            &[7],
            &[0],
        )
        .expect("built-in label map is valid")
    }

    /// Checks that no label is given two meanings and that there is a region and a bone.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let bad = |m: String| Err(GeometryError::InvalidLabelMap(m));
        if self.regions.is_empty() {
            return bad("no region labels (expected e.g. 1=fat,2=quadriceps)".into());
        }
        if self.bone.is_empty() {
            return bad("no bone label".into());
        }
        let mut seen: BTreeMap<u32, String> = BTreeMap::new();
        let items = self
            .regions
            .iter()
            .map(|(l, n)| (*l, format!("region {n}")))
            .chain(self.bone.iter().map(|&l| (l, "bone".to_string())))
            .chain(
                self.background
                    .iter()
                    .map(|&l| (l, "background".to_string())),
            );
        for (l, what) in items {
            if let Some(prev) = seen.insert(l, what.clone()) {
                if prev != what || what == "bone" || what == "background" {
                    return bad(format!("label {l} is given twice ({prev} and {what})"));
                }
                return bad(format!("label {l} is mapped twice"));
            }
        }
        Ok(())
    }

    /// Region names in order of first appearance.
    pub fn region_names(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for (_, n) in &self.regions {
            if !names.contains(n) {
                names.push(n.clone());
            }
        }
        names
    }
}

/// Parses `1=fat,2=quadriceps,6=ischio`: comma-separated `label=region`; region names are
/// upper-cased (they become element-set names: letters, digits, `_` and `-`, starting with a
/// letter).
pub fn parse_label_map(text: &str) -> Result<Vec<(u32, String)>, GeometryError> {
    let mut out = Vec::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let Some((l, n)) = item.split_once('=') else {
            return Err(GeometryError::InvalidLabelMap(format!(
                "'{item}' is not LABEL=REGION"
            )));
        };
        let label: u32 = l.trim().parse().map_err(|_| {
            GeometryError::InvalidLabelMap(format!(
                "'{}' in '{item}' is not a non-negative integer label",
                l.trim()
            ))
        })?;
        let name = n.trim().to_ascii_uppercase();
        let valid = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !valid {
            return Err(GeometryError::InvalidLabelMap(format!(
                "region name '{}' in '{item}' must start with a letter and hold only letters, digits, '_' or '-'",
                n.trim()
            )));
        }
        if matches!(name.as_str(), "FEMUR" | "SKIN" | "NALL" | "ALL") {
            return Err(GeometryError::InvalidLabelMap(format!(
                "region name '{name}' is reserved (it names a boundary set)"
            )));
        }
        out.push((label, name));
    }
    if out.is_empty() {
        return Err(GeometryError::InvalidLabelMap(
            "empty map (expected e.g. 1=fat,2=quadriceps)".into(),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_maps_parse_and_validate() {
        let m = parse_label_map("1=fat, 2=Quadriceps,6=ischio,3=ischio").unwrap();
        assert_eq!(m[1], (2, "QUADRICEPS".to_string()));
        assert!(parse_label_map("1:fat").is_err());
        assert!(parse_label_map("x=fat").is_err());
        assert!(parse_label_map("1=2fat").is_err());
        assert!(parse_label_map("1=femur").is_err());
        assert!(LabelSpec::new("1=fat,1=ischio", &[7], &[0]).is_err());
        assert!(LabelSpec::new("1=fat", &[1], &[0]).is_err());
        assert!(LabelSpec::new("1=fat", &[7], &[7]).is_err());
        let s = LabelSpec::thigh_mri();
        assert_eq!(
            s.region_names(),
            ["FAT", "QUADRICEPS", "ISCHIO", "GRACILIS", "SARTORIUS"]
        );
    }

    #[test]
    fn rows_are_flipped_upwards() {
        let img = LabelImage::from_rows_top_down(2, 2, &[1, 2, 3, 4]);
        assert_eq!(img.get(0, 0), 3);
        assert_eq!(img.get(1, 1), 2);
        assert_eq!(img.histogram()[&4], 1);
    }
}
