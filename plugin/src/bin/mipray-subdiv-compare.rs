//! `mipray-subdiv-compare`: the project's subdivision results compared with OpenSubdiv's, for one
//! mesh in OpenSubdiv's regression-shape OBJ format (`t` tags). See docs/subdivision-compare.md.
//!
//! ```text
//! mipray-subdiv-compare ../shared/osd-shapes/catmark_pole8.obj
//! mipray-subdiv-compare --json --level 3 --heatmap pole8.png shape.obj
//! ```
//! A readable table goes to stdout (one JSON object with `--json`); one-line errors to stderr.
//! Exit status: 0 when compared, 1 on failure (including shapes refused as not supported), 2 for
//! a bad command line. USD meshes (`file.usda:/Prim/Path`) are read by the Python command of
//! the same name (`python -m mipray.tools.subdiv_compare`), which calls the same comparison.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use hd_mipray::subdiv_compare::heatmap::{self, HeatmapOptions};
use hd_mipray::subdiv_compare::{compare_obj, CompareOptions};
use mipray::image_io::{ChannelFormat, ImageIo};
use mipray::obj_shape::parse_obj_shape;
use mipray::tessellate::Rate;
use mipray_bridge::{OiioImageIo, OsdSurface};

const PROG: &str = "mipray-subdiv-compare";

const USAGE: &str = "usage: mipray-subdiv-compare [--json] [--heatmap FILE.png] [--heatmap-rate 1|2|4|8|16]
                             [--level K] [--samples S] [--patches N] [--split-depth D]
                             [--split-patches N] [--quick] SHAPE.obj

Compares mipray's limit evaluation, tessellations (each tier, each rate, split children) and
seams with OpenSubdiv's own limit evaluation and uniform refinement. Errors are relative to the
control mesh's bounding-box diagonal.

  --json              print one JSON object instead of a table
  --heatmap FILE      draw the tessellation error on the surface (PNG, EXR, ...)
  --heatmap-rate R    the rate drawn, quads per patch side (default 4)
  --level K           OpenSubdiv uniform refinement level to compare with (default 2; 0 skips)
  --samples S         limit samples per patch side (default 5)
  --patches N         patches whose tessellations are measured (default 512; 0 = all)
  --split-depth D     deepest split measured (default 2)
  --split-patches N   patches whose split children are measured (default 64; 0 = all)
  --quick             the corpus test's small settings";

struct Args {
    json: bool,
    heatmap: Option<String>,
    heatmap_rate: Rate,
    options: CompareOptions,
    input: String,
}

fn parse_args(argv: &[String]) -> Result<Option<Args>> {
    let mut options = CompareOptions::default();
    let (mut json, mut heatmap, mut heatmap_rate, mut input) = (false, None, Rate::R4, None);
    let mut it = argv.iter();
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().cloned().with_context(|| format!("{name} needs a value"));
        let mut number = |name: &str| -> Result<usize> {
            let v = value(name)?;
            v.parse::<usize>().with_context(|| format!("{name} {v:?} is not a whole number"))
        };
        match a.as_str() {
            "-h" | "--help" => return Ok(None),
            "--json" => json = true,
            "--quick" => options = CompareOptions { osd: options.osd, ..CompareOptions::quick() },
            "--heatmap" => heatmap = Some(value("--heatmap")?),
            "--heatmap-rate" => {
                let r = number("--heatmap-rate")?;
                heatmap_rate = Rate::ALL
                    .into_iter()
                    .find(|x| x.quads() == r)
                    .with_context(|| format!("--heatmap-rate {r} is not one of 1, 2, 4, 8, 16"))?;
            }
            "--level" => options.uniform_level = u32::try_from(number("--level")?.min(10)).unwrap_or(10),
            "--samples" => options.samples_per_side = number("--samples")?.clamp(2, 65),
            "--patches" => options.tessellation_patches = number("--patches")?,
            "--split-depth" => options.split_depth = u32::try_from(number("--split-depth")?.min(6)).unwrap_or(6),
            "--split-patches" => options.split_patches = number("--split-patches")?,
            s if s.starts_with('-') => bail!("unknown option {s}"),
            s => {
                if input.replace(s.to_string()).is_some() {
                    bail!("one input at a time");
                }
            }
        }
    }
    let input = input.context("no input shape")?;
    Ok(Some(Args { json, heatmap, heatmap_rate, options, input }))
}

fn run(args: &Args) -> Result<()> {
    let path = Path::new(&args.input);
    if args.input.contains(".usd") && args.input.contains(':') && !path.exists() {
        bail!("{}: USD meshes are read by the Python command: python -m mipray.tools.subdiv_compare {}", args.input, args.input);
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", args.input))?;
    let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("shape");
    let report = compare_obj(name, &text, &args.options)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", report.table());
    }
    if let Some(out) = &args.heatmap {
        let shape = parse_obj_shape(name, &text)?;
        let surface = OsdSurface::with_options(name, &shape.topology, &shape.points, &args.options.osd)?;
        let img = heatmap::render(&surface, report.bbox_diagonal, &HeatmapOptions { rate: args.heatmap_rate, ..Default::default() });
        OiioImageIo.write(Path::new(out), &img, &[ChannelFormat::U8], &[])?;
        if !args.json {
            println!(
                "{:<44} {out} (rate {}, log10 error {} .. {})",
                "heatmap",
                args.heatmap_rate.quads(),
                heatmap::LOG_RANGE.0,
                heatmap::LOG_RANGE.1
            );
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let args = match parse_args(&argv) {
        Ok(Some(a)) => a,
        Ok(None) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("{PROG}: {e:#} (see --help)");
            return ExitCode::from(2);
        }
    };
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{PROG}: {e:#}");
            ExitCode::FAILURE
        }
    }
}
