//! Shared by the bridge's texture tests: scratch directories, the OpenImageIO command-line
//! tools (Debian's openimageio-tools, which `scripts/setup.sh` installs), and one-channel test
//! images written through [`OiioImageIo`].
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray_bridge::OiioImageIo;

/// A directory of this process for test `test` of suite `suite`, made if missing.
pub fn scratch_dir(suite: &str, test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mipray-{suite}-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Panics, naming the tool and what installs it, unless `tool` runs: a missing tool must fail
/// the test, not turn it into a silent pass.
pub fn require(tool: &str) {
    let ok = Command::new(tool).arg("--help").output().is_ok_and(|o| o.status.success() || !o.stdout.is_empty());
    assert!(ok, "`{tool}` (Debian's openimageio-tools) is not on the PATH: run scripts/setup.sh, which installs it");
}

/// Runs `cmd`, panicking with its stderr if it fails.
pub fn run(cmd: &mut Command) {
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{cmd:?} failed: {}", String::from_utf8_lossy(&out.stderr));
}

/// A one-channel (`Y`) `res`² image, texel (x, row from the top) = `f(x, row)`, written in
/// `dir` as `name` in `format`.
pub fn write(dir: &Path, name: &str, res: usize, format: ChannelFormat, f: impl Fn(usize, usize) -> f32) -> PathBuf {
    let pixels = (0..res * res).map(|k| f(k % res, k / res)).collect();
    let path = dir.join(name);
    OiioImageIo
        .write(&path, &ImageBuf { width: res, height: res, channels: vec!["Y".into()], pixels, metadata: vec![] }, &[format], &[])
        .unwrap();
    path
}

/// `maketx src -o dst --filter box` with `args` after: a tiled MIP map of box-filtered levels.
pub fn maketx(src: &Path, dst: &Path, args: &[&str]) -> PathBuf {
    run(Command::new("maketx").arg(src).arg("-o").arg(dst).args(["--filter", "box"]).args(args));
    dst.to_path_buf()
}
