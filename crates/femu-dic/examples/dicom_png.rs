//! Writes one frame of a DICOM (or PNG/TIFF) file as an 8-bit grey PNG, with its header summary:
//! `cargo run -p femu-dic --example dicom_png -- FILE FRAME OUT.png`.
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() != 4 {
        return Err("usage: dicom_png FILE FRAME OUT.png".into());
    }
    let path = std::path::Path::new(&a[1]);
    if femu_dic::dicom::is_dicom(path) {
        println!("{:?}", femu_dic::dicom::dicom_info(path)?);
    }
    let img = femu_dic::GreyImage::open(path, a[2].parse()?)?;
    img.save_png(std::path::Path::new(&a[3]))?;
    Ok(())
}
