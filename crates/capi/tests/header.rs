//! The committed header is the one cbindgen generates from the code: a change to the C
//! interface that is not in `include/stereonav.h` fails here. `SN_BLESS=1` writes it.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

#[test]
fn the_committed_header_is_the_generated_one() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen reads the C interface")
        .write(&mut generated);
    let path = dir.join("include/stereonav.h");
    if std::env::var_os("SN_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "include/stereonav.h differs from what cbindgen generates from src/lib.rs: \
         run `SN_BLESS=1 cargo test -p stereonav-capi --test header` and commit it"
    );
    let text = String::from_utf8(generated).unwrap();
    for fixed in [
        "#define SN_ABI_VERSION 1",
        "uint32_t sn_abi_version(void);",
        "size_t sn_last_error(char *buf, size_t len);",
        "int sn_navigator_new(const char *rig, size_t rig_len, sn_navigator **out);",
        "void sn_navigator_free(sn_navigator *nav);",
        "int sn_localizer_pose(const sn_localizer *loc, sn_pose *out);",
    ] {
        assert!(text.contains(fixed), "the header lacks {fixed:?}");
    }
}
