use harris_core::{Registers, detect, reference};
#[test]
fn euroc_matches_reference() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/euroc-v101-stereo/left");
    let mut paths: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    paths.sort();
    let img = image::open(&paths[0]).unwrap().into_luma8();
    let regs = Registers { width: img.width() as usize, height: img.height() as usize, ..Registers::default() };
    let d = detect(img.as_raw(), &regs).unwrap();
    let r = reference::integer(img.as_raw(), &regs).unwrap();
    println!("{} {} {}", d.features.len(), r.all_features.len(), d.overflow);
    assert_eq!(d.features, r.features);
    assert_eq!(d.overflow, r.overflow);
    assert_eq!(harris_core::response_map(img.as_raw(), &regs).unwrap(), r.response);
}
