//! Several pictures side by side: panels written by the other functions (each with its own axes
//! and colour bar) tiled into one PNG, row by row — a figure of the seed's Fig. 8 kind (one
//! panel per parameter and test).

use crate::PlotError;
use std::path::Path;

/// Tiles the PNG `panels` into a grid of `columns` columns (row-major, white background; panels
/// of different sizes are placed in cells as large as the largest) and writes it to `path`.
pub fn tile_png(path: &Path, panels: &[&Path], columns: usize) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::Empty("no panel to tile".into()));
    }
    if columns == 0 {
        return Err(PlotError::InvalidOption(
            "columns must be at least 1".into(),
        ));
    }
    let images = panels
        .iter()
        .map(|p| {
            image::open(p)
                .map(|i| i.to_rgb8())
                .map_err(|e| PlotError::InvalidData(format!("{}: {e}", p.display())))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let cw = images.iter().map(|i| i.width()).max().unwrap_or(1);
    let ch = images.iter().map(|i| i.height()).max().unwrap_or(1);
    let cols = columns.min(images.len()) as u32;
    let rows = images.len().div_ceil(columns) as u32;
    let mut out = image::RgbImage::from_pixel(cw * cols, ch * rows, image::Rgb([255, 255, 255]));
    for (k, img) in images.iter().enumerate() {
        let (c, r) = ((k % columns) as u32, (k / columns) as u32);
        image::imageops::replace(&mut out, img, (c * cw) as i64, (r * ch) as i64);
    }
    crate::save_png(path, &out).map_err(|e| PlotError::Write {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_row_major_and_refuses_nothing() {
        let dir = std::env::temp_dir().join(format!("femu-tile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut paths = Vec::new();
        for (k, grey) in [0u8, 80, 160].iter().enumerate() {
            let p = dir.join(format!("p{k}.png"));
            image::RgbImage::from_pixel(4, 3, image::Rgb([*grey; 3]))
                .save(&p)
                .unwrap();
            paths.push(p);
        }
        let refs: Vec<&Path> = paths.iter().map(|p| p.as_path()).collect();
        let out = dir.join("tiled.png");
        tile_png(&out, &refs, 2).unwrap();
        let t = image::open(&out).unwrap().to_rgb8();
        assert_eq!((t.width(), t.height()), (8, 6));
        assert_eq!(t.get_pixel(5, 1).0, [80; 3]); // second panel, first row
        assert_eq!(t.get_pixel(1, 4).0, [160; 3]); // third panel, second row
        assert_eq!(t.get_pixel(6, 4).0, [255; 3]); // empty cell
        assert!(tile_png(&out, &[], 2).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
