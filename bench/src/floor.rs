//! `opacity-floor`: how well can *any* single surface score under render consistency (issue #34,
//! docs/conventions.md §8), on a given set of Gaussians? Two measurements on the held-out rig
//! `trisplat eval MESH --gaussians G.ply` uses (rig A):
//!
//! - **The views' mutual consistency.** Every covered pixel of view a (alpha > 1/2) lifted to 3D
//!   at its median depth and projected into every other view b: where b covers the pixel it falls
//!   in, the signed difference `s = z_b(p) - D_b` (b's median depth read bilinearly where its
//!   four pixel centres agree). `s < 0` means that a's surface point lies in front of what b
//!   shows, in b's free space: a *conflict* that no single surface escapes (a surface through p
//!   is hit by b's ray at depth `<= z_b(p)`); `s > 0` can be an occlusion and is not a conflict.
//!   Also: a's points that fall on b's uncovered pixels (a surface through them adds silhouette
//!   that b does not have). Per pixel of a, the worst conflict over the other views; every
//!   figure split by where the pixel lies in a: the rim (within 2 px of a's silhouette), fuzzy
//!   (the expected depth more than `--fuzzy` from the median depth: several layers blend) and
//!   solid (the rest).
//! - **Oracles.** Surfaces built from rig A's own median-depth maps (the evaluation views
//!   themselves): TSDF fusion at each `--voxel`, and the median-depth field carved by them
//!   (`median_depth_mesh`, one view carves, small margin, depth samples). Each is written to
//!   the output folder and scored on rig A (the views it was built from) and on rig B, a second
//!   rig of the same size turned `--second-rotation` degrees away (written as `rig_b.json`, so
//!   `trisplat eval MESH --gaussians G.ply --cameras rig_b.json` scores it again).
//!
//! Also writes a picture per view of a's worst conflict (PPM, 0..10 mm black to red, white:
//! silhouette conflicts, grey: no conflict) for the first `--pictures` views.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use trisplat_extract::opacity::{
    DepthRules, DepthView, KeepPieces, OpacityOptions, median_depth_mesh,
};
use trisplat_extract::tsdf::{DepthImage, TsdfOptions, fuse};
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer, NormalFrame};
use trisplat_geometry::{Camera, TriMesh, bounding_sphere, sphere_rig, write_cameras_json};
use trisplat_pipeline::consistency::{
    CONSISTENCY_FOV_DEG, CONSISTENCY_RESOLUTION, CONSISTENCY_VIEWS, COVERED_ALPHA, GaussianViews,
    held_out_rig,
};
use trisplat_pipeline::opacity::opacity_gaussians;
use trisplat_splat::GaussianSet;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::render::{Outputs, RenderOptions, render};

/// Options of `opacity-floor`.
#[derive(Debug, clap::Args)]
pub struct FloorArgs {
    /// World-space Gaussians (3DGS PLY), e.g. a frame of `trisplat deform`.
    #[arg(long)]
    pub gaussians: PathBuf,
    /// Output folder (created; meshes, rigs and pictures).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Views of each rig (as `trisplat eval --views`).
    #[arg(long, default_value_t = CONSISTENCY_VIEWS)]
    pub views: usize,
    /// Image size of each rig (as `trisplat eval --resolution`).
    #[arg(long, default_value_t = CONSISTENCY_RESOLUTION)]
    pub resolution: u32,
    /// Rig B: rig A's lattice turned this many more degrees about (1, -1, 1).
    #[arg(long, default_value_t = 23.0)]
    pub second_rotation: f64,
    /// TSDF voxel sizes (scene units), comma separated.
    #[arg(long, value_delimiter = ',', default_value = "0.002,0.001")]
    pub voxel: Vec<f64>,
    /// Carved oracles `K:M`, comma separated: the median-depth field of rig A's own maps, a
    /// point outside when K views carve it with a margin of M footprints (a huge M: the
    /// visual hull of the silhouettes), vertices settled onto the median depth.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1:0.5,2:0.5,4:0.5,8:0.5,1:1000"
    )]
    pub carve: Vec<String>,
    /// TSDF truncation, in voxels.
    #[arg(long, default_value_t = 4.0)]
    pub trunc_voxels: f64,
    /// A pixel is fuzzy when its expected depth lies more than this from its median depth.
    #[arg(long, default_value_t = 0.002)]
    pub fuzzy: f64,
    /// Pictures of the first N views' conflicts.
    #[arg(long, default_value_t = 4)]
    pub pictures: usize,
    /// Other meshes to score the same way, split by region (repeatable).
    #[arg(long)]
    pub mesh: Vec<PathBuf>,
    /// Skip the oracles (only the mutual consistency and `--mesh`).
    #[arg(long)]
    pub no_oracles: bool,
}

/// Where a pixel lies in its view.
const REGIONS: [&str; 3] = ["rim", "fuzzy", "solid"];
/// Rim: within this many pixels (Chebyshev) of an uncovered pixel.
const RIM_PX: i64 = 2;

/// One rig's renders.
struct Maps {
    /// The camera and its median z-depth where alpha > 1/2, else 0 (what render consistency
    /// compares with).
    view: DepthView,
    /// Region of each covered pixel (index into [`REGIONS`]); `u8::MAX` where uncovered.
    region: Vec<u8>,
}

fn render_maps(set: &GaussianSet, cameras: &[Camera], fuzzy: f64) -> anyhow::Result<Vec<Maps>> {
    let options = RenderOptions {
        outputs: Outputs {
            rgb: false,
            alpha: true,
            depth: true,
            median_depth: true,
            normal: false,
        },
        normal_frame: NormalFrame::World,
        ..RenderOptions::default()
    };
    cameras
        .par_iter()
        .map(|camera| {
            let out = render(set, camera, &options)
                .with_context(|| format!("rendering {}", camera.name))?;
            let images = out.images;
            let (Some(alpha), Some(mut depth), Some(expected)) =
                (images.alpha, images.median_depth, images.depth)
            else {
                bail!("a render without the images asked for");
            };
            for (z, a) in depth.iter_mut().zip(&alpha) {
                if !(*a > COVERED_ALPHA && z.is_finite() && *z > 0.0) {
                    *z = 0.0;
                }
            }
            let (w, h) = (i64::from(camera.width), i64::from(camera.height));
            let covered = |c: i64, r: i64| {
                c >= 0 && r >= 0 && c < w && r < h && depth[(r * w + c) as usize] > 0.0
            };
            let region = (0..w * h)
                .map(|k| {
                    let (c, r) = (k % w, k / w);
                    let d = depth[k as usize];
                    if d <= 0.0 {
                        return u8::MAX;
                    }
                    let rim = (-RIM_PX..=RIM_PX)
                        .any(|dr| (-RIM_PX..=RIM_PX).any(|dc| !covered(c + dc, r + dr)));
                    if rim {
                        0
                    } else if (f64::from(expected[k as usize]) - f64::from(d)).abs() > fuzzy {
                        1
                    } else {
                        2
                    }
                })
                .collect();
            Ok(Maps {
                view: DepthView {
                    camera: camera.clone(),
                    depth,
                    rgb: Vec::new(),
                },
                region,
            })
        })
        .collect()
}

/// Where world point `p` falls in `m`: its camera z, `m`'s median depth there ([`DepthView::median_at`]; 0
/// uncovered) and the pixel's index; `None` behind the camera or outside the image.
fn seen_in(m: &Maps, p: DVec3) -> Option<(f64, f64, usize)> {
    let cam = &m.view.camera;
    let q = cam.world_to_camera(p);
    if q.z <= 1e-9 {
        return None;
    }
    let uv = cam.project(q);
    let inside =
        uv.x >= 0.0 && uv.y >= 0.0 && uv.x < f64::from(cam.width) && uv.y < f64::from(cam.height);
    inside.then(|| {
        let pixel = (uv.y as usize) * cam.width as usize + uv.x as usize;
        (
            q.z,
            m.view.median_at(0.5 * (cam.fx + cam.fy), uv.x, uv.y),
            pixel,
        )
    })
}

/// Per region (and all): the pair differences and per-pixel worst conflicts.
#[derive(Default)]
struct Tally {
    /// Signed `z_b(p) - D_b` over co-covered pairs.
    signed: Vec<f64>,
    /// Pairs where p falls on an uncovered pixel of b (inside b's image).
    silhouette: usize,
    /// Pairs where p falls in b's image.
    in_image: usize,
    /// Per pixel of a: the largest `D_b - z_b(p)` over the co-covered b (0 when none > 0).
    worst: Vec<f64>,
    /// Pixels of a with some b that sees p on an uncovered pixel.
    silhouette_pixels: usize,
}

impl Tally {
    fn absorb(&mut self, o: Self) {
        self.signed.extend(o.signed);
        self.silhouette += o.silhouette;
        self.in_image += o.in_image;
        self.worst.extend(o.worst);
        self.silhouette_pixels += o.silhouette_pixels;
    }
}

/// The mutual consistency of `maps`, per region of the lifting view (plus all, last).
fn mutual(maps: &[Maps]) -> (Vec<Tally>, Vec<Conflict>) {
    let per_view: Vec<(Vec<Tally>, Vec<Conflict>)> = (0..maps.len())
        .into_par_iter()
        .map(|a| {
            let ma = &maps[a];
            let cam = &ma.view.camera;
            let (w, h) = (cam.width as usize, cam.height as usize);
            let mut tallies: Vec<Tally> = (0..REGIONS.len()).map(|_| Tally::default()).collect();
            let mut conflicts = Vec::new();
            for k in 0..w * h {
                let d = f64::from(ma.view.depth[k]);
                if d <= 0.0 {
                    continue;
                }
                let t = &mut tallies[usize::from(ma.region[k])];
                let ray = cam.unproject((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
                let p = cam.camera_to_world(ray * d);
                let mut worst = 0.0f64;
                let mut off = false;
                for (b, mb) in maps.iter().enumerate() {
                    if b == a {
                        continue;
                    }
                    let Some((z, db, y)) = seen_in(mb, p) else {
                        continue;
                    };
                    t.in_image += 1;
                    if db <= 0.0 {
                        t.silhouette += 1;
                        off = true;
                        continue;
                    }
                    let s = z - db;
                    t.signed.push(s);
                    worst = worst.max(-s);
                    if -s > MATCH_THRESHOLDS[0] {
                        conflicts.push(Conflict {
                            x: (a * w * h + k) as u32,
                            y: (b * w * h + y) as u32,
                            c: -s as f32,
                        });
                    }
                }
                t.worst.push(worst);
                t.silhouette_pixels += usize::from(off);
            }
            (tallies, conflicts)
        })
        .collect();
    let mut edges = Vec::new();
    let mut out: Vec<Tally> = (0..=REGIONS.len()).map(|_| Tally::default()).collect();
    for (tallies, c) in per_view {
        edges.extend(c);
        for (r, t) in tallies.into_iter().enumerate() {
            out[r].absorb(t);
        }
    }
    let mut all = Tally::default();
    for t in &out[..REGIONS.len()] {
        all.signed.extend(&t.signed);
        all.silhouette += t.silhouette;
        all.in_image += t.in_image;
        all.worst.extend(&t.worst);
        all.silhouette_pixels += t.silhouette_pixels;
    }
    out[REGIONS.len()] = all;
    (out, edges)
}

/// A free-space conflict: pixel `x` (view-major global index) lifted at its median depth lies
/// `c` metres in front of the median depth of pixel `y` of another view.
struct Conflict {
    x: u32,
    y: u32,
    c: f32,
}

/// Conflict sizes of the matching bound: `2 t` for the error thresholds `t` of 1 and 5 mm (the
/// goals' median and 90th percentile).
const MATCH_THRESHOLDS: [f64; 2] = [0.002, 0.010];

/// A greedy maximal matching in the graph of conflicts larger than `threshold` (edges in their
/// order): the matched edges share no pixel, and each needs one of its two pixels missed or in
/// error by more than `threshold / 2` (a surface within `t` of x's median point is hit by y's
/// ray at least `c - t` in front of y's median depth; pixel quantisation aside), so every
/// surface has at least this many such pixels.
fn matching(edges: &[Conflict], pixels: usize, threshold: f64) -> usize {
    let mut used = vec![false; pixels];
    let mut size = 0;
    for e in edges.iter().filter(|e| f64::from(e.c) > threshold) {
        let (x, y) = (e.x as usize, e.y as usize);
        if !used[x] && !used[y] {
            used[x] = true;
            used[y] = true;
            size += 1;
        }
    }
    size
}

/// The pictures of [`mutual`] (recomputed per view: cheap next to the renders).
fn conflict_pictures(maps: &[Maps], count: usize, dir: &Path) -> anyhow::Result<()> {
    for a in 0..count.min(maps.len()) {
        let ma = &maps[a];
        let cam = &ma.view.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut ppm = format!("P6\n{w} {h}\n255\n").into_bytes();
        for k in 0..w * h {
            let d = f64::from(ma.view.depth[k]);
            if d <= 0.0 {
                ppm.extend_from_slice(&[0, 0, 64]);
                continue;
            }
            let p =
                cam.camera_to_world(cam.unproject((k % w) as f64 + 0.5, (k / w) as f64 + 0.5) * d);
            let (mut worst, mut off) = (0.0f64, false);
            for (b, mb) in maps.iter().enumerate() {
                let Some((z, db, _)) = seen_in(mb, p).filter(|_| b != a) else {
                    continue;
                };
                if db <= 0.0 {
                    off = true;
                } else {
                    worst = worst.max(db - z);
                }
            }
            let px = if off {
                [255, 255, 255]
            } else if worst <= 0.001 {
                [96, 96, 96]
            } else {
                let t = ((worst - 0.001) / 0.009).clamp(0.0, 1.0);
                [(64.0 + 191.0 * t) as u8, (64.0 * (1.0 - t)) as u8, 0]
            };
            ppm.extend_from_slice(&px);
        }
        let path = dir.join(format!("conflict_{}.ppm", cam.name));
        std::fs::write(&path, ppm).with_context(|| format!("{}", path.display()))?;
    }
    Ok(())
}

/// The `q`-quantile (numpy's linear rule) of `v`, reordering it; NaN when empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_unstable_by(f64::total_cmp);
    let at = q * (v.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    v[lo] + (v[hi] - v[lo]) * (at - lo as f64)
}

/// A mesh's render consistency split by the region of each Gaussian-covered pixel: per region
/// the pixels the mesh misses, and the median / 90th percentile of |mesh depth - median depth|
/// (in mm); the mesh's extra pixels (hit where the Gaussians are uncovered) in the last row.
fn split_score(mesh: &TriMesh, maps: &[Maps]) -> anyhow::Result<String> {
    let renderer = MeshRenderer::new(
        mesh,
        MeshRenderOptions {
            frame: NormalFrame::World,
            ..MeshRenderOptions::default()
        },
    )?;
    let mut errors: Vec<Vec<f64>> = vec![Vec::new(); REGIONS.len()];
    let mut missing = vec![0usize; REGIONS.len()];
    let mut covered = vec![0usize; REGIONS.len()];
    let mut extra = 0usize;
    for m in maps {
        let r = renderer.render(&m.view.camera);
        for (k, (&g, &z)) in m.view.depth.iter().zip(&r.depth).enumerate() {
            match (g > 0.0, z > 0.0) {
                (true, true) => {
                    let reg = usize::from(m.region[k]);
                    covered[reg] += 1;
                    errors[reg].push((f64::from(z) - f64::from(g)).abs());
                }
                (true, false) => {
                    let reg = usize::from(m.region[k]);
                    covered[reg] += 1;
                    missing[reg] += 1;
                }
                (false, true) => extra += 1,
                (false, false) => {}
            }
        }
    }
    let mut s = String::new();
    for (r, name) in REGIONS.iter().enumerate() {
        let n = errors[r].len();
        writeln!(
            s,
            "      {name:>5}: {:>7} px, missed {:>6}, |err| median {:.2} mm, p90 {:.2} mm, share of the errors > 5 mm {:.2}",
            covered[r],
            missing[r],
            1e3 * quantile(&mut errors[r], 0.5),
            1e3 * quantile(&mut errors[r], 0.9),
            errors[r].iter().filter(|&&e| e > 0.005).count() as f64 / n.max(1) as f64
        )?;
    }
    writeln!(s, "      extra px (mesh hit, Gaussians uncovered): {extra}")?;
    Ok(s)
}

/// Rig B: rig A's construction with the lattice turned `degrees` more, about (1, -1, 1).
fn second_rig(
    set: &GaussianSet,
    views: usize,
    resolution: u32,
    degrees: f64,
) -> anyhow::Result<Vec<Camera>> {
    let a = held_out_rig(set, views, resolution)?;
    let (center, _) = bounding_sphere(&[], set.means()).context("no finite Gaussian")?;
    let turn = DQuat::from_axis_angle(DVec3::new(1.0, -1.0, 1.0).normalize(), degrees.to_radians());
    let _ = sphere_rig; // The lattice is rig A's (itself a sphere_rig), turned once more.
    a.iter()
        .map(|c| {
            let eye = center + turn * (c.position() - center);
            let mut cam = Camera::look_at(
                format!("b_{}", c.name),
                eye,
                center,
                DVec3::Y,
                (resolution, resolution),
                CONSISTENCY_FOV_DEG,
            )?;
            cam.id = c.id;
            Ok(cam)
        })
        .collect()
}

/// The smallest angle (degrees) between a view direction of `a` and one of `b`, seen from
/// `center`.
fn closest_angle(a: &[Camera], b: &[Camera], center: DVec3) -> f64 {
    let mut best = f64::INFINITY;
    for x in a {
        for y in b {
            let (u, v) = (
                (x.position() - center).normalize(),
                (y.position() - center).normalize(),
            );
            best = best.min(u.dot(v).clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    best
}

/// Runs the measurement and prints it.
///
/// # Errors
/// Unreadable Gaussians, an existing output folder, a failed render, fusion or write.
pub fn run(args: &FloorArgs) -> anyhow::Result<()> {
    if args.output.exists() {
        bail!("{}: exists; not overwritten", args.output.display());
    }
    let clock = Instant::now();
    let set =
        read_gaussians(&args.gaussians).with_context(|| format!("{}", args.gaussians.display()))?;
    let rig_a = held_out_rig(&set, args.views, args.resolution)?;
    let rig_b = second_rig(&set, args.views, args.resolution, args.second_rotation)?;
    let (center, _) = bounding_sphere(&[], set.means()).context("no finite Gaussian")?;
    std::fs::create_dir_all(&args.output)?;
    write_cameras_json(&args.output.join("rig_a.json"), &rig_a)?;
    write_cameras_json(&args.output.join("rig_b.json"), &rig_b)?;
    let maps = render_maps(&set, &rig_a, args.fuzzy)?;
    let maps_b = render_maps(&set, &rig_b, args.fuzzy)?;
    let mut report = String::new();
    writeln!(
        report,
        "{}: {} Gaussians; rig A = eval's held-out rig ({} views, {}^2), rig B turned {} deg (closest view pair {:.1} deg apart); renders {:.1} s",
        args.gaussians.display(),
        set.len(),
        args.views,
        args.resolution,
        args.second_rotation,
        closest_angle(&rig_a, &rig_b, center),
        clock.elapsed().as_secs_f64()
    )?;

    // The views' mutual consistency.
    let (mut tallies, edges) = mutual(&maps);
    writeln!(
        report,
        "mutual consistency of rig A (pairs: a's covered pixel lifted at its median depth, seen in b):"
    )?;
    for (r, t) in tallies.iter_mut().enumerate() {
        let name = REGIONS.get(r).copied().unwrap_or("all");
        let pixels = t.worst.len();
        let pairs = t.signed.len();
        let mut abs: Vec<f64> = t.signed.iter().map(|s| s.abs()).collect();
        let conflicts =
            |x: f64| t.signed.iter().filter(|&&s| -s > x).count() as f64 / pairs.max(1) as f64;
        let (c1, c5) = (conflicts(0.001), conflicts(0.005));
        let worst_over =
            |x: f64| t.worst.iter().filter(|&&c| c > x).count() as f64 / pixels.max(1) as f64;
        let (w1, w5) = (worst_over(0.001), worst_over(0.005));
        writeln!(
            report,
            "  {name:>5}: {pixels:>7} px of a, {pairs:>8} co-covered pairs; signed z_b - D_b p10/p50/p90 {:.2}/{:.2}/{:.2} mm, |.| median {:.2} p90 {:.2} mm",
            1e3 * quantile(&mut t.signed, 0.1),
            1e3 * quantile(&mut t.signed, 0.5),
            1e3 * quantile(&mut t.signed, 0.9),
            1e3 * quantile(&mut abs, 0.5),
            1e3 * quantile(&mut abs, 0.9),
        )?;
        writeln!(
            report,
            "         conflicts (a's point in b's free space) > 1 mm: {:.1}% of pairs, > 5 mm: {:.1}%; per pixel of a, worst over b: median {:.2} mm, p90 {:.2} mm, > 1 mm {:.1}%, > 5 mm {:.1}%; on b's uncovered pixels: {:.1}% of pairs, {:.1}% of a's pixels",
            100.0 * c1,
            100.0 * c5,
            1e3 * quantile(&mut t.worst, 0.5),
            1e3 * quantile(&mut t.worst, 0.9),
            100.0 * w1,
            100.0 * w5,
            100.0 * t.silhouette as f64 / t.in_image.max(1) as f64,
            100.0 * t.silhouette_pixels as f64 / pixels.max(1) as f64,
        )?;
    }
    let all_pixels: usize = maps.iter().map(|m| m.view.depth.len()).sum();
    let covered = tallies[REGIONS.len()].worst.len();
    for threshold in MATCH_THRESHOLDS {
        let m = matching(&edges, all_pixels, threshold);
        writeln!(
            report,
            "  matching bound: {m} disjoint pairs with a conflict > {:.0} mm, so any surface misses or errs by > {:.1} mm on at least {m} pixels = {:.1}% of the {covered} covered",
            threshold * 1e3,
            threshold * 0.5e3,
            100.0 * m as f64 / covered.max(1) as f64
        )?;
    }
    conflict_pictures(&maps, args.pictures, &args.output)?;
    print!("{report}");

    // The oracles, scored on both rigs.
    let views_a = GaussianViews::render(&set, &rig_a)?;
    let views_b = GaussianViews::render(&set, &rig_b)?;
    let mut oracles: Vec<(String, TriMesh, f64)> = Vec::new();
    for path in &args.mesh {
        let mesh = read_mesh(path).with_context(|| format!("{}", path.display()))?;
        oracles.push((format!("given {}", path.display()), mesh, 0.0));
    }
    let voxels: &[f64] = if args.no_oracles { &[] } else { &args.voxel };
    for &voxel in voxels {
        let clock = Instant::now();
        let depths: Vec<DepthImage> = maps
            .iter()
            .map(|m| {
                DepthImage::try_new(
                    m.view.camera.width,
                    m.view.camera.height,
                    m.view.depth.clone(),
                )
            })
            .collect::<Result<_, _>>()?;
        let options = TsdfOptions {
            voxel: Some(voxel),
            trunc: Some(args.trunc_voxels * voxel),
            keep_clusters: 0,
            ..TsdfOptions::default()
        };
        let fused = fuse(&rig_a, &depths, None, &options)?;
        oracles.push((
            format!("tsdf_{:.1}mm", voxel * 1e3),
            fused.mesh,
            clock.elapsed().as_secs_f64(),
        ));
    }
    let g = opacity_gaussians(&set);
    let depth_views: Vec<DepthView> = maps.iter().map(|m| m.view.clone()).collect();
    let carved: Vec<(u16, f32)> = if args.no_oracles {
        Vec::new()
    } else {
        args.carve
            .iter()
            .map(|c| {
                let (k, m) = c
                    .split_once(':')
                    .with_context(|| format!("--carve {c}: expected K:M"))?;
                Ok((k.parse()?, m.parse()?))
            })
            .collect::<anyhow::Result<_>>()?
    };
    for &(k, margin) in &carved {
        let clock = Instant::now();
        let rules = DepthRules {
            margin,
            carve_views: k,
            sample_stride: if margin > 100.0 { 0 } else { 2 },
            surface: if margin > 100.0 { margin } else { 0.0 },
        };
        let options = OpacityOptions {
            colors: false,
            keep: KeepPieces::All,
            ..OpacityOptions::default()
        };
        let out = median_depth_mesh(&g, &depth_views, rules, &options, None)?;
        oracles.push((
            format!("carved_k{k}_m{margin}"),
            out.mesh,
            clock.elapsed().as_secs_f64(),
        ));
    }
    for (name, mesh, seconds) in &oracles {
        if !name.starts_with("given ") {
            let path = args.output.join(format!("{name}.ply"));
            write_mesh(&path, mesh, WriteOptions::default())?;
        }
        let (a, b) = (views_a.score(mesh)?, views_b.score(mesh)?);
        let mm = |x: Option<f64>| x.map_or(f64::NAN, |v| v * 1e3);
        println!(
            "oracle {name} ({} triangles, {seconds:.1} s): rig A (built from) IoU {:.4}, median {:.2} mm, p90 {:.2} mm; rig B (held out) IoU {:.4}, median {:.2} mm, p90 {:.2} mm",
            mesh.triangle_count(),
            a.iou,
            mm(a.depth_error_median),
            mm(a.depth_error_p90),
            b.iou,
            mm(b.depth_error_median),
            mm(b.depth_error_p90),
        );
        println!("    rig A by region:\n{}", split_score(mesh, &maps)?);
        println!("    rig B by region:\n{}", split_score(mesh, &maps_b)?);
    }
    println!("whole run {:.1} s", clock.elapsed().as_secs_f64());
    Ok(())
}
