//! Compiles the Delaunay tessellation under the medial axis: Qhull's reentrant C library as
//! vendored (vendor/qhull_r, unmodified, see its README.md) and our shim over it
//! (csrc/delaunay.c), with the `cc` crate. A C compiler is all it needs: no bindgen, no libclang
//! (src/centerline_extract/qhull.rs declares the shim's two functions by hand).

use std::path::PathBuf;

/// Qhull's files that vesselhex does not call: rbox (Qhull's point generator) and the
/// accessors made for other languages' bindings.
const UNUSED: [&str; 3] = ["rboxlib_r.c", "userprintf_rbox_r.c", "accessors_r.c"];

fn main() {
    let qhull = PathBuf::from("vendor/qhull_r");
    println!("cargo:rerun-if-changed=csrc/delaunay.c");
    println!("cargo:rerun-if-changed={}", qhull.display());
    let mut sources: Vec<PathBuf> = std::fs::read_dir(&qhull)
        .expect("vendor/qhull_r: Qhull's sources")
        .map(|entry| entry.expect("vendor/qhull_r").path())
        .filter(|p| p.extension().is_some_and(|e| e == "c"))
        .filter(|p| !UNUSED.iter().any(|u| p.file_name().is_some_and(|n| n == *u)))
        .collect();
    sources.sort(); // the same object order on every file system
                    // The shim first: the linker reads the libraries in order, and the shim calls into Qhull.
    cc::Build::new().file("csrc/delaunay.c").include(&qhull).compile("vesselhex_delaunay");
    // Qhull as published: its warnings are not ours to fix.
    cc::Build::new().files(&sources).include(&qhull).warnings(false).compile("qhull_r");
}
