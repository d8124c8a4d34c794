//! trisplat: Gaussian avatars built around the explicit triangle mesh, on the CPU.
//!
//! This crate is the front door of the library: it re-exports the layers (each also usable on
//! its own) and shows the main entry points. Conventions (frames, formats, renderer rules,
//! metric definitions) are in `docs/conventions.md`; the crate map in `ARCHITECTURE.md`.
//!
//! | module | crate | what |
//! |---|---|---|
//! | [`geometry`] | `trisplat-geometry` | meshes, I/O (PLY, OBJ, glTF), cameras, spatial indexes, metrics, sampling, smoothing, animation |
//! | [`splat`] | `trisplat-splat` | Gaussian sets, INRIA PLY, binding, deformation, densify/prune, the CPU renderer |
//! | [`extract`] | `trisplat-extract` | TSDF fusion + marching cubes, incremental Delaunay, alpha shapes |
//! | [`pipeline`] | `trisplat-pipeline` | the main job: a [`Session`] per run, frame by frame; `refine`, the surface-guided re-initialisation |
//!
//! # Read a mesh
//! ```
//! use trisplat::geometry::io::read_mesh;
//!
//! let mesh = read_mesh(&trisplat_fixtures::path("spot_triangulated.obj"))?;
//! assert_eq!(mesh.triangle_count(), 5856);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Bind Gaussians to its triangles, deform them with the mesh
//! ```
//! use trisplat::geometry::io::read_mesh;
//! use trisplat::splat::{BindOptions, init_bound};
//! use trisplat::splat::{DeformMode, Deformer};
//!
//! let mesh = read_mesh(&trisplat_fixtures::path("spot_triangulated.obj"))?;
//! // One Gaussian per triangle at its centroid (GaussianAvatars' initialisation).
//! let bound = init_bound(&mesh, &BindOptions::default())?;
//! // Move the mesh (here: lift it by 1), and the Gaussians follow their triangles.
//! let moved: Vec<_> = mesh.positions().iter().map(|p| *p + glam::DVec3::Y).collect();
//! let world = Deformer::new(&mesh, DeformMode::Binding).deform(&bound, &moved)?;
//! assert_eq!(world.len(), mesh.triangle_count());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Render depth on the CPU
//! ```
//! use trisplat::geometry::sphere_rig;
//! use trisplat::geometry::io::read_mesh;
//! use trisplat::splat::{BindOptions, init_bound};
//! use trisplat::splat::{DeformMode, Deformer};
//! use trisplat::splat::render::{RenderOptions, render};
//!
//! let mesh = read_mesh(&trisplat_fixtures::path("spot_triangulated.obj"))?;
//! let bound = init_bound(&mesh, &BindOptions { opacity: 0.9, ..BindOptions::default() })?;
//! let world = Deformer::new(&mesh, DeformMode::Binding).deform(&bound, mesh.positions())?;
//! let bounds = mesh.bounds().expect("finite");
//! let radius = (bounds.max - bounds.min).length() / 2.0;
//! let cameras = sphere_rig(bounds.center(), radius, 1, (64, 64), 40.0)?;
//! let out = render(&world, &cameras[0], &RenderOptions::default())?;
//! let depth = out.images.depth.expect("depth is rendered by default");
//! assert!(depth.iter().any(|&z| z > 0.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Extract meshes: one call, or the main job frame by frame
//! ```
//! use trisplat::extract::alpha_shape::alpha_shape;
//! use trisplat::pipeline::{ExtractConfig, ExtractOptions, Method, Session};
//!
//! // An alpha shape of points.
//! let corners: Vec<glam::Vec3> = (0..8)
//!     .map(|i| glam::Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, (i >> 2) as f32))
//!     .collect();
//! let cube = alpha_shape(&corners, 10.0)?;
//! assert_eq!(cube.mesh.triangle_count(), 12);
//!
//! // The main job: a skinned glTF playing its own clip, Gaussians bound here, one
//! // incremental Delaunay mesh per frame (what `trisplat extract` writes to disk).
//! let config = ExtractConfig {
//!     template: trisplat_fixtures::path("anim/RiggedFigure.glb"),
//!     animation: None,
//!     gaussians: None,
//!     methods: vec![Method::Delaunay],
//!     output: "unused".into(),
//!     frames: Some("0..2".to_owned()),
//!     gt: None,
//!     options: ExtractOptions::default(),
//! };
//! let mut session = Session::open(&config)?;
//! for f in session.frames() {
//!     let frame = session.frame(f)?;
//!     assert!(frame.methods[0].output.mesh.triangle_count() > 0);
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Re-initialise bound Gaussians on the surface of their centres (VGA/GVA)
//! ```
//! use trisplat::geometry::io::read_mesh;
//! use trisplat::pipeline::refine::{RefineOptions, refine};
//! use trisplat::splat::{BindOptions, init_bound};
//! use trisplat::splat::TriangleCounts;
//!
//! let mesh = read_mesh(&trisplat_fixtures::path("spot_triangulated.obj"))?;
//! let bound = init_bound(&mesh, &BindOptions { per_triangle: 2, ..BindOptions::default() })?;
//! // Alpha shape of the centres, smoothed, resampled; new Gaussians inherit from their
//! // nearest old ones and stay bound; the seed's pruning (ε_o 0.015, ε_n 0.3, k 5).
//! let refined = refine(&bound, &mesh, &RefineOptions::default(), |round, _surfaces| {
//!     println!("{} Gaussians, Chamfer L1 {:.4}", round.after, round.chamfer_after.chamfer_l1);
//! })?;
//! let counts = TriangleCounts::from_set(&refined.set, mesh.triangle_count())?;
//! assert!(counts.counts().iter().all(|&c| c > 0)); // no triangle emptied
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Measure a mesh against a reference
//! ```
//! use trisplat::geometry::io::read_mesh;
//! use trisplat::geometry::metrics::{MetricsOptions, Shape, evaluate};
//! use trisplat::geometry::sampling::sample_uniform;
//!
//! let pred = read_mesh(&trisplat_fixtures::path("spot_taubin.ply"))?;
//! let gt = read_mesh(&trisplat_fixtures::path("spot_triangulated.obj"))?;
//! let (p, g) = (sample_uniform(&pred, 10_000, 0), sample_uniform(&gt, 10_000, 1));
//! let options = MetricsOptions { taus: vec![0.005], surface: true };
//! let m = evaluate(Shape::mesh(&pred, &p), Shape::mesh(&gt, &g), &options)?;
//! assert!(m.chamfer_l1 < 0.01 && m.thresholds[0].fscore > 0.5);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub use trisplat_extract as extract;
pub use trisplat_geometry as geometry;
pub use trisplat_pipeline as pipeline;
pub use trisplat_pipeline::{ExtractConfig, Session};
pub use trisplat_splat as splat;
