//! The gallery example is a test too: it writes its seven pictures, each a 1200 x 900 PNG.

#[allow(dead_code)]
#[path = "../examples/gallery.rs"]
mod gallery;

#[test]
fn gallery_writes_every_picture() {
    let dir = std::env::temp_dir().join(format!("femu-plot-gallery-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let written = gallery::write_gallery(&dir).unwrap();
    assert_eq!(written.len(), 7);
    for p in written {
        let img = image::open(&p).unwrap();
        assert_eq!((img.width(), img.height()), (1200, 900), "{}", p.display());
    }
}
