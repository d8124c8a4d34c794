//! `trisplat demo [-o DIR]`: the main job on the bundled avatar fixture.

use std::path::{Path, PathBuf};
use trisplat_pipeline::config::AnimationOptions;

use anyhow::Context as _;
use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_pipeline::{ExtractConfig, ExtractOptions, GroundTruth, Method, RunControl};

use super::Context;
use super::extract::run_and_summarise;

/// File name of the bundled avatar, written into the output folder: Khronos' CesiumMan
/// (CC BY 4.0, © Cesium), a skinned walk cycle.
pub const DEMO_FIXTURE: &str = "CesiumMan.glb";

/// The bundled avatar's bytes, embedded in the binary so that the demo runs anywhere (also
/// after `cargo install`, away from the source checkout).
const DEMO_GLB: &[u8] = include_bytes!("../../../fixtures/data/anim/CesiumMan.glb");

/// Its licence and attribution, written beside it.
const DEMO_LICENCE: &str = "CesiumMan.glb: Khronos glTF sample model, unchanged \
(https://github.com/KhronosGroup/glTF-Sample-Assets).\n\
Licence: CC BY 4.0 International (https://creativecommons.org/licenses/by/4.0/legalcode), \
(c) Cesium. Attribution: Cesium; the Cesium trademark is not licensed.\n";

/// File name of the licence written beside the avatar.
pub const DEMO_LICENCE_FILE: &str = "CesiumMan_LICENSE.txt";

/// Frames per second at which the demo samples the walk cycle (a handful of frames).
pub const DEMO_FPS: f64 = 3.0;

/// Arguments of `trisplat demo`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Runs the main job on the bundled avatar (CesiumMan.glb, embedded in the binary: Khronos glTF \
sample model, CC BY 4.0, (c) Cesium; 3,273 vertices, 2,338 once the UV seams are welded, 4,672 \
triangles, a skinned walk cycle). It is \
the same as

  trisplat extract --template DIR/CesiumMan.glb --fps 3 \\
      --method tsdf,delaunay,alpha --gt template -o DIR

binding 4 Gaussians per triangle itself, meshing the walk cycle sampled at 3 frames per second \
with all three methods, and measuring each frame against the deformed template. It prints a \
table (method, ms/frame, Chamfer L1) and where the outputs are (see `trisplat extract --help`). \
The avatar and its licence are written to DIR/CesiumMan.glb and DIR/CesiumMan_LICENSE.txt \
first, so the demo needs no file beside the binary.")]
pub struct DemoArgs {
    /// Output folder (created if missing).
    #[arg(
        short = 'o',
        long = "output",
        value_name = "DIR",
        default_value = "trisplat-demo"
    )]
    pub output: PathBuf,
}

/// Runs `trisplat demo`.
///
/// # Errors
/// An output folder that cannot be written, or whatever the pipeline reports.
pub fn run(args: DemoArgs, ctx: &Context) -> anyhow::Result<()> {
    let template = write_avatar(&args.output)?;
    let config = ExtractConfig {
        template,
        animation: None,
        gaussians: None,
        // The three established methods; opacity is far slower per frame (docs/benchmarks.md).
        methods: vec![Method::Tsdf, Method::Delaunay, Method::Alpha],
        output: args.output,
        frames: None,
        gt: Some(GroundTruth::Template),
        options: ExtractOptions {
            animation: AnimationOptions {
                fps: DEMO_FPS,
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    };
    if !ctx.json {
        println!(
            "trisplat demo: {} (bundled; CC BY 4.0, (c) Cesium), methods tsdf, delaunay, alpha, \
             ground truth: the deformed template",
            config.template.display()
        );
    }
    // The demo always starts over in its folder.
    let control = RunControl {
        force: true,
        ..RunControl::default()
    };
    run_and_summarise(&config, control, ("demo", ctx))
}

/// Writes the embedded avatar and its licence into `dir` (created if missing); returns the
/// avatar's path.
fn write_avatar(dir: &Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<PathBuf> {
        let path = dir.join(name);
        write_atomically(&path, |w| {
            w.write_all(bytes).map_err(|e| IoError::os(&path, e))
        })?;
        Ok(path)
    };
    write(DEMO_LICENCE_FILE, DEMO_LICENCE.as_bytes())?;
    write(DEMO_FIXTURE, DEMO_GLB)
}
