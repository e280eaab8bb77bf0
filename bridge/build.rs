//! Builds the C++ side of the bridge (`cpp/`, `include/`) with cxx and links OpenSubdiv (osdCPU)
//! and OpenImageIO.
//!
//! OpenImageIO ships a pkg-config file. OpenSubdiv ships only CMake config files, so it is looked
//! for by pkg-config first (some distributions add one), then under `OSD_ROOT` (a prefix with
//! `include/` and `lib/`), then in the system include directories.

use std::env;
use std::path::{Path, PathBuf};

/// The header whose presence marks an OpenSubdiv installation.
const OSD_PROBE_HEADER: &str = "opensubdiv/far/topologyRefiner.h";

fn main() {
    for f in ["src/ffi.rs", "cpp/osd.cpp", "cpp/oiio.cpp", "cpp/texture.cpp", "include/osd.h", "include/oiio.h", "include/texture.h"] {
        println!("cargo:rerun-if-changed={f}");
    }
    println!("cargo:rerun-if-env-changed=OSD_ROOT");

    let mut include_dirs: Vec<PathBuf> = Vec::new();

    let oiio = pkg_config::Config::new().atleast_version("2.4").probe("OpenImageIO").unwrap_or_else(|e| {
        fail(&format!("OpenImageIO >= 2.4 not found by pkg-config ({e}); install libopenimageio-dev or set PKG_CONFIG_PATH"))
    });
    include_dirs.extend(oiio.include_paths);

    include_dirs.extend(find_opensubdiv());

    let mut build = cxx_build::bridge("src/ffi.rs");
    build
        .file("cpp/osd.cpp")
        .file("cpp/oiio.cpp")
        .file("cpp/texture.cpp")
        .std("c++17")
        // OpenSubdiv's and OpenImageIO's headers are not warning-clean; ours should be.
        .flag_if_supported("-Wno-unused-parameter")
        .flag_if_supported("-Wno-deprecated-declarations");
    for dir in &include_dirs {
        build.include(dir);
    }
    build.compile("mipray_bridge_cpp");
}

/// Finds OpenSubdiv, emits its link flags, and returns extra include directories (empty when
/// the headers are in a default search path).
fn find_opensubdiv() -> Vec<PathBuf> {
    // 1. pkg-config, under the names distributions use.
    for name in ["opensubdiv", "OpenSubdiv", "osdCPU"] {
        if let Ok(lib) = pkg_config::Config::new().cargo_metadata(false).probe(name) {
            for dir in &lib.link_paths {
                println!("cargo:rustc-link-search=native={}", dir.display());
            }
            println!("cargo:rustc-link-lib=osdCPU");
            return lib.include_paths;
        }
    }

    // 2. OSD_ROOT: an installation prefix.
    if let Some(root) = env::var_os("OSD_ROOT").map(PathBuf::from) {
        let include = root.join("include");
        if !include.join(OSD_PROBE_HEADER).is_file() {
            fail(&format!("OSD_ROOT={} has no include/{OSD_PROBE_HEADER}", root.display()));
        }
        for lib in ["lib", "lib64", "lib/x86_64-linux-gnu", "lib/aarch64-linux-gnu"] {
            let dir = root.join(lib);
            if dir.is_dir() {
                println!("cargo:rustc-link-search=native={}", dir.display());
            }
        }
        println!("cargo:rustc-link-lib=osdCPU");
        return vec![include];
    }

    // 3. The system include directories.
    for prefix in ["/usr", "/usr/local"] {
        let include = Path::new(prefix).join("include");
        if include.join(OSD_PROBE_HEADER).is_file() {
            if prefix != "/usr" {
                // /usr/lib is searched by default; /usr/local/lib is not always.
                for lib in ["lib", "lib64"] {
                    let dir = Path::new(prefix).join(lib);
                    if dir.is_dir() {
                        println!("cargo:rustc-link-search=native={}", dir.display());
                    }
                }
            }
            println!("cargo:rustc-link-lib=osdCPU");
            return if prefix == "/usr" { Vec::new() } else { vec![include] };
        }
    }

    fail(&format!(
        "OpenSubdiv not found: no pkg-config file, OSD_ROOT unset, and no {OSD_PROBE_HEADER} under \
         /usr/include or /usr/local/include; install libosd-dev or set OSD_ROOT to its prefix"
    ))
}

fn fail(message: &str) -> ! {
    // A build script reports by failing; the message is what the user sees.
    eprintln!("mipray-bridge: {message}");
    panic!("mipray-bridge: {message}");
}
