//! `trisplat demo [-o DIR]`: the main job on the bundled avatar fixture.

use std::path::PathBuf;

use anyhow::bail;
use trisplat_pipeline::{ExtractConfig, ExtractOptions, GroundTruth, Method};

use super::Context;
use super::extract::{print_summary, run_with_progress};

/// The bundled avatar: Khronos' CesiumMan (CC BY 4.0, © Cesium), a skinned walk cycle.
pub const DEMO_FIXTURE: &str = "anim/CesiumMan.glb";

/// Frames per second at which the demo samples the walk cycle (a handful of frames).
pub const DEMO_FPS: f64 = 3.0;

/// Arguments of `trisplat demo`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Runs the main job on the bundled avatar (fixtures/data/anim/CesiumMan.glb: Khronos glTF sample \
model, CC BY 4.0, (c) Cesium; 3,273 vertices, 2,338 once the UV seams are welded, 4,672 \
triangles, a skinned walk cycle). It is \
the same as

  trisplat extract --template fixtures/data/anim/CesiumMan.glb --fps 3 \\
      --method tsdf,delaunay,alpha --gt template -o DIR

binding 4 Gaussians per triangle itself, meshing the walk cycle sampled at 3 frames per second \
with all three methods, and measuring each frame against the deformed template. It prints a \
table (method, ms/frame, Chamfer L1) and where the outputs are (see `trisplat extract --help`). \
The fixture is found in the source checkout the binary was built from.")]
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
/// A missing fixture (a binary moved away from its checkout), or whatever the pipeline reports.
pub fn run(args: DemoArgs, ctx: &Context) -> anyhow::Result<()> {
    let template = trisplat_fixtures::path(DEMO_FIXTURE);
    if !template.is_file() {
        bail!(
            "{}: the demo's fixture is missing (the demo reads it from the source checkout the \
             binary was built from); run `trisplat extract --template YOUR.glb ...` instead",
            template.display()
        );
    }
    let config = ExtractConfig {
        template,
        animation: None,
        gaussians: None,
        methods: Method::ALL.to_vec(),
        output: args.output,
        frames: None,
        gt: Some(GroundTruth::Template),
        options: ExtractOptions {
            fps: DEMO_FPS,
            ..ExtractOptions::default()
        },
    };
    println!(
        "trisplat demo: {} (CC BY 4.0, (c) Cesium), methods tsdf, delaunay, alpha, ground truth: \
         the deformed template",
        config.template.display()
    );
    let report = run_with_progress(&config, ctx)?;
    print_summary(&report, &config.output);
    Ok(())
}
