//! What a run writes for people to look at: the plot as SVG (well-formed, naming every method
//! and its axes) and PNG, report.html (self-contained: the plot inline, every file it links or
//! shows exists, the means' cells as report.md has them) with one thumbnail per method and
//! the ground truth, and the frame meshes coloured by their distance to the ground truth when
//! asked (`--error-colors`); also without a ground truth, after `--resume` and after `merge`.

use std::path::{Path, PathBuf};
use trisplat_pipeline::config::{MetricOptions, OutputOptions, TsdfOptions};

use trisplat_geometry::TriMesh;
use trisplat_geometry::io::read_mesh;
use trisplat_pipeline::merge;
use trisplat_pipeline::metrics::GtSamples;
use trisplat_pipeline::report::thumbnail::{THUMBNAIL_HEIGHT, viridis};
use trisplat_pipeline::{
    ExtractConfig, ExtractOptions, GroundTruth, Method, Report, RunControl, Session, run,
};

/// RiggedFigure (370 vertices, a skinned clip): small enough to mesh by every method.
fn config(
    out: &Path,
    methods: &[Method],
    frames: &str,
    gt: Option<GroundTruth>,
    error_colors: bool,
) -> ExtractConfig {
    ExtractConfig {
        template: trisplat_fixtures::path("anim/RiggedFigure.glb"),
        animation: None,
        gaussians: None,
        methods: methods.to_vec(),
        output: out.to_path_buf(),
        frames: Some(frames.to_owned()),
        gt,
        options: ExtractOptions {
            tsdf: TsdfOptions {
                views: 6,
                resolution: 64,
                ..Default::default()
            },
            metrics: MetricOptions {
                samples: 2000,
                ..Default::default()
            },
            outputs: OutputOptions {
                error_colors,
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    }
}

fn run_ok(config: &ExtractConfig, control: RunControl) -> Report {
    run(config, control, &mut |_| {}).expect("run")
}

/// Checks that `text` is well-formed markup as far as tags go: every `<name …>` is closed by
/// `</name>` in order, or closes itself (`<name …/>`); comments, `<!DOCTYPE>` and the void
/// elements of HTML (`meta`, `img`, `br`) stand alone.
fn assert_tags_balance(text: &str, what: &str) {
    let mut stack: Vec<String> = Vec::new();
    let mut rest = text;
    while let Some(start) = rest.find('<') {
        let after = &rest[start + 1..];
        let end = after
            .find('>')
            .unwrap_or_else(|| panic!("{what}: a tag is not closed"));
        let tag = &after[..end];
        rest = &after[end + 1..];
        if tag.starts_with('!') {
            continue;
        }
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack
                .pop()
                .unwrap_or_else(|| panic!("{what}: </{name}> closes nothing"));
            assert_eq!(open, name.trim(), "{what}: <{open}> closed by </{name}>");
            continue;
        }
        let name: String = tag
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        assert!(!name.is_empty(), "{what}: bad tag <{tag}>");
        if !tag.ends_with('/') && !["meta", "img", "br"].contains(&name.as_str()) {
            stack.push(name);
        }
    }
    assert!(stack.is_empty(), "{what}: unclosed {stack:?}");
}

/// The values of `attribute="…"` in `html`.
fn attribute_values(html: &str, attribute: &str) -> Vec<String> {
    let key = format!(" {attribute}=\"");
    html.match_indices(&key)
        .map(|(at, _)| {
            let value = &html[at + key.len()..];
            value[..value.find('"').expect("closing quote")].to_owned()
        })
        .collect()
}

/// Checks report.html in `out`: balanced tags, the plot inline, every relative link and
/// image names a file or folder of the run; returns the page.
fn check_html(out: &Path, report: &Report) -> String {
    let html = std::fs::read_to_string(out.join("report.html")).expect("report.html");
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_tags_balance(&html, "report.html");
    // The plot inline, as the SVG file holds it.
    let svg = std::fs::read_to_string(out.join("error_vs_time.svg")).expect("svg");
    assert!(html.contains(svg.trim()), "the plot is inline");
    // Everything it names is there, relative to the page.
    let mut named = attribute_values(&html, "href");
    named.extend(attribute_values(&html, "src"));
    for target in named.iter().filter(|t| !t.starts_with('#')) {
        assert!(
            !target.contains("://"),
            "{target}: the page is self-contained"
        );
        assert!(out.join(target).exists(), "{target} linked but missing");
    }
    for m in report.ordered() {
        assert!(named.contains(&m.glb), "{}", m.glb);
        assert!(named.contains(&format!("{}/", m.ply_dir)));
    }
    for file in [
        "report.json",
        "report.md",
        "error_vs_time.svg",
        "error_vs_time.png",
    ] {
        assert!(named.iter().any(|n| n == file), "{file} not linked");
    }
    // The means as report.md has them.
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    for row in &report.summary_table().rows {
        for cell in row {
            let text = trisplat_pipeline::report::html::escape(&cell.text);
            assert!(
                html.contains(&format!(">{text}<")),
                "{} not in the page",
                cell.text
            );
            assert!(md.contains(&cell.text), "{} not in report.md", cell.text);
        }
    }
    // report.md shows the SVG and links the page.
    assert!(md.contains("](error_vs_time.svg)") && md.contains("](report.html)"));
    html
}

/// The PNG at `path`: its pixels.
fn png(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

#[test]
fn plot_page_thumbnails_and_error_colours_of_a_measured_run() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run");
    let methods = [Method::Tsdf, Method::Delaunay, Method::Alpha];
    let cfg = config(&out, &methods, "0..3", Some(GroundTruth::Template), true);
    let report = run_ok(&cfg, RunControl::default());

    // The SVG: one document, every method labelled (delaunay starred: its meshes hold the
    // template's vertices), the axes with their units.
    let svg = std::fs::read_to_string(out.join("error_vs_time.svg")).expect("svg");
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert_tags_balance(&svg, "error_vs_time.svg");
    for label in ["tsdf", "delaunay *", "alpha"] {
        assert!(svg.contains(&format!(">\n{label}\n</text>")), "{label}");
    }
    assert!(svg.contains("time per frame, ms (log scale)"));
    assert!(svg.contains("Chamfer L1 to the ground truth, scene units (log scale)"));
    assert!(svg.contains("self-consistency, not"));
    let plot = png(&out.join("error_vs_time.png"));
    assert_eq!(plot.dimensions(), (960, 560));

    // The thumbnails: the middle frame, each method and the ground truth, one camera.
    let t = report.thumbnails.as_ref().expect("thumbnails");
    assert_eq!(t.frame, 1);
    let names: Vec<&str> = t.methods.keys().map(String::as_str).collect();
    assert_eq!(names, ["alpha", "delaunay", "tsdf"]);
    let tau = report.methods["tsdf"].frames[1]
        .metrics
        .as_ref()
        .expect("measured")
        .tau;
    assert_eq!(t.scale, Some(2.0 * tau));
    let gt_file = t.ground_truth.as_ref().expect("ground truth picture");
    let gt_picture = png(&out.join(gt_file));
    assert_eq!(gt_picture.height(), THUMBNAIL_HEIGHT);
    let is_grey = |p: &image::Rgb<u8>| p.0[0] == p.0[1] && p.0[1] == p.0[2];
    assert!(gt_picture.pixels().all(is_grey), "the ground truth is grey");
    for (name, file) in &t.methods {
        let picture = png(&out.join(file));
        assert_eq!(picture.dimensions(), gt_picture.dimensions(), "{name}");
        let coloured = picture.pixels().filter(|p| !is_grey(p)).count();
        assert!(coloured > 1000, "{name}: {coloured} coloured pixels");
    }
    let html = check_html(&out, &report);
    assert!(html.contains(&format!("src=\"{gt_file}\"")));
    assert!(html.contains("The meshes of frame 1"));
    assert!(html.contains("linear-gradient"), "the colour scale");

    // Error colours: each vertex's distance to the frame's deformed template through the
    // colour map, from 0 to twice the frame's threshold.
    let mut session = Session::open(&cfg).expect("session");
    for f in 0..3 {
        let positions = session.positions(f).expect("frame positions");
        let template = TriMesh::new_unchecked(positions, session.template().triangles().to_vec());
        let gt = GtSamples::new(template, 100).expect("ground truth");
        for m in &methods {
            let path = out.join(m.name()).join(format!("frame_{f:06}.ply"));
            let mesh = read_mesh(&path).expect("frame");
            let colours = mesh.colors().expect("colours");
            assert_eq!(colours.len(), mesh.vertex_count());
            let tau = report.methods[m.name()].frames[f]
                .metrics
                .as_ref()
                .expect("measured")
                .tau;
            let mut distinct = std::collections::BTreeSet::new();
            for (v, c) in mesh.positions().iter().zip(colours) {
                let d = gt.distance(*v).expect("distance");
                let got = [c[0], c[1], c[2]].map(|x| (x * 255.0).round() as u8);
                assert_eq!(
                    got,
                    viridis(d / (2.0 * tau)),
                    "{}: distance {d}",
                    path.display()
                );
                assert_eq!(c[3], 1.0);
                distinct.insert(got);
            }
            assert!(
                distinct.len() > 3,
                "{}: {} colours",
                path.display(),
                distinct.len()
            );
        }
    }

    // Without --error-colors the frames carry the Gaussians' colours (the default), and none
    // with --vertex-colors off.
    let plain = dir.path().join("plain");
    let mut cfg = config(
        &plain,
        &[Method::Delaunay],
        "0..1",
        Some(GroundTruth::Template),
        false,
    );
    run_ok(&cfg, RunControl::default());
    let mesh = read_mesh(&plain.join("delaunay/frame_000000.ply")).expect("frame");
    assert!(mesh.colors().is_some());
    let off = dir.path().join("off");
    cfg.output.clone_from(&off);
    cfg.options.finish.vertex_colors = trisplat_pipeline::config::VertexColors::Off;
    run_ok(&cfg, RunControl::default());
    let mesh = read_mesh(&off.join("delaunay/frame_000000.ply")).expect("frame");
    assert!(mesh.colors().is_none());
}

#[test]
fn error_colours_need_a_ground_truth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cfg = config(
        &dir.path().join("run"),
        &[Method::Delaunay],
        "0..1",
        None,
        true,
    );
    let err = run(&cfg, RunControl::default(), &mut |_| {}).expect_err("refused");
    assert!(err.to_string().contains("--error-colors"), "{err}");
    assert!(!dir.path().join("run").join("report.json").exists());
}

#[test]
fn without_ground_truth_the_page_shows_times_and_grey_meshes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run");
    let report = run_ok(
        &config(
            &out,
            &[Method::Delaunay, Method::Alpha],
            "0..2",
            None,
            false,
        ),
        RunControl::default(),
    );
    let svg = std::fs::read_to_string(out.join("error_vs_time.svg")).expect("svg");
    assert!(svg.contains("no ground truth") && svg.contains("animation frame"));
    let t = report.thumbnails.as_ref().expect("thumbnails");
    assert_eq!((t.frame, t.scale, t.ground_truth.as_ref()), (0, None, None));
    for file in t.methods.values() {
        let picture = png(&out.join(file));
        assert!(
            picture.pixels().any(|p| p.0 != [255; 3]),
            "{file} shows a mesh"
        );
        assert!(
            picture
                .pixels()
                .all(|p| p.0[0] == p.0[1] && p.0[1] == p.0[2])
        );
    }
    let html = check_html(&out, &report);
    assert!(
        !html.contains("linear-gradient"),
        "no colour scale without distances"
    );
}

#[test]
fn resumed_and_merged_runs_keep_their_thumbnails() {
    let dir = tempfile::tempdir().expect("temp dir");
    let gt = Some(GroundTruth::Template);
    // A finished run resumed: nothing runs again, the report still shows frame 1's pictures.
    let out = dir.path().join("run");
    let cfg = config(&out, &[Method::Delaunay], "0..3", gt.clone(), false);
    let first = run_ok(&cfg, RunControl::default());
    std::fs::remove_file(out.join("report.html")).expect("rm page");
    let resumed = run_ok(
        &cfg,
        RunControl {
            resume: true,
            ..RunControl::default()
        },
    );
    assert_eq!(resumed.thumbnails, first.thumbnails);
    check_html(&out, &resumed);
    // Two shards merged: the pictures of the shard nearer the middle come along.
    let shards: Vec<PathBuf> = ["0..2", "2..5"]
        .iter()
        .enumerate()
        .map(|(k, frames)| {
            let shard = dir.path().join(format!("shard{k}"));
            run_ok(
                &config(&shard, &[Method::Delaunay], frames, gt.clone(), false),
                RunControl::default(),
            );
            shard
        })
        .collect();
    let merged_dir = dir.path().join("merged");
    let merged = merge(&shards, &merged_dir, false).expect("merge");
    let t = merged.thumbnails.as_ref().expect("thumbnails");
    // Shard 0 pictures frame 0, shard 1 frame 3; the middle of frames 0-4 is 2.
    assert_eq!(t.frame, 3);
    assert!(merged_dir.join(&t.methods["delaunay"]).is_file());
    check_html(&merged_dir, &merged);
}
