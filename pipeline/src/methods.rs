//! The four meshers, each turning one deformed frame into a mesh, and the scale-derived
//! defaults of their parameters. Delaunay and alpha see only the means of the Gaussians
//! [`crate::Visibility`] keeps; tsdf renders every Gaussian of the frame.
//!
//! - **tsdf**: a sphere rig of `views` cameras (geometry's `sphere_rig`, 40° field of view)
//!   and a voxel grid anchored to the avatar's best-fitting rigid motion ([`crate::anchor`],
//!   `--tsdf-anchor rigid`), or in world space around the bounding sphere of the frame
//!   (deformed template and every Gaussian's mean; `--tsdf-anchor world`),
//!   expected or median depth ([`DepthKind`]) rendered from the deformed Gaussians (3DGS,
//!   gsplat rules) and masked where the rendered alpha is below `tsdf_alpha_cut` (default
//!   [`RENDERED_ALPHA_MIN`]), fused with the extract crate's TSDF at
//!   `voxel` (default: [`default_voxel`], the Gaussians' mean spacing within template radius
//!   / 128 ..= / 32), truncation 5 voxels, depth truncation twice the rig's scene radius,
//!   largest connected piece kept.
//! - **delaunay**: [`IncrementalDelaunay`] over the rest template and the Gaussians' canonical
//!   means; each frame moves vertices and redoes only the charts Gaussians hopped into or out
//!   of (`hop_threshold` lets Gaussians stay in a chart they left by less than that many mean
//!   template edges; `rebuild_every` forces full rebuilds, and updates that cost more than
//!   rebuilds are followed by rebuilds unless `no_auto_rebuild`); [`MethodOutput::delaunay`] says
//!   what each update did.
//! - **alpha**: the alpha complex of the deformed means (the extract crate's `alpha_complex`:
//!   regular and singular triangles; by default only the boundary of the solid it encloses,
//!   `AlphaRule::Solid`) at the smallest α from
//!   [`DEFAULT_ALPHA_FLOOR_SPACINGS`] to [`DEFAULT_ALPHA_CEILING_SPACINGS`] mean spacings of
//!   the rest-pose means whose mesh has at most `alpha.pieces` pieces, searched per frame; or
//!   at a fixed `alpha`; or Open3D's alpha shape (`AlphaRule::Open3d`, default
//!   [`DEFAULT_ALPHA_SPACINGS`] spacings); optionally only its largest edge-connected pieces
//!   (`alpha_keep_clusters`).
//! - **opacity**: the opacity field of every deformed Gaussian (Gaussian Opacity Fields, the
//!   extract crate's `opacity`) from the tsdf method's rig (`views`, `resolution`), framed
//!   around the Gaussians and their 3-sigma boxes: by default each point's side read from the
//!   rig's rendered median-depth maps (`--opacity-field median`; `gof`: GOF's opacity along
//!   rays), and only the largest piece (`--opacity-pieces`).

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{DVec3, Vec3};
use trisplat_extract::alpha_complex::{AlphaComplex, AlphaSearch, smallest_connected_alpha};
use trisplat_extract::alpha_shape::{AlphaShape, alpha_shape};
use trisplat_extract::delaunay3d::Delaunay3d;
use trisplat_extract::incremental_delaunay::{DelaunayOptions, FrameStats, IncrementalDelaunay};
use trisplat_extract::opacity::{
    DEFAULT_BISECTION_STEPS as OPACITY_BISECTION_STEPS, DEFAULT_LEVEL as OPACITY_LEVEL,
    DepthRules as MedianRules, KeepPieces, MAJOR_PIECE_FRACTION, OpacityOptions, OpacityTrack,
    median_depth_mesh, opacity_mesh_tracked,
};
use trisplat_extract::tsdf::{ColorImage, DepthImage, TsdfError, TsdfOptions, fuse};
use trisplat_geometry::Camera;
use trisplat_geometry::TriMesh;
use trisplat_geometry::cleanup::keep_largest_clusters;
use trisplat_geometry::spatial::PointIndex;
use trisplat_geometry::{bounding_sphere, sphere_rig};
use trisplat_splat::GaussianSet;
use trisplat_splat::render::{Outputs, RenderError, RenderOptions, render, render_front};

use crate::anchor::AnchoredRig;
use crate::config::{
    ALPHA_STEPS_PER_DOUBLING, AlphaRule, COARSEST_VOXELS_PER_RADIUS,
    DEFAULT_ALPHA_CEILING_SPACINGS, DEFAULT_ALPHA_FLOOR_SPACINGS, DEFAULT_ALPHA_SPACINGS,
    DEFAULT_FOV_DEG, DEFAULT_FRONT_ALPHA, DEFAULT_VOXELS_PER_RADIUS, DepthKind, ExtractOptions,
    Method, OpacityField, OpacityPieces, RENDERED_ALPHA_MIN, SimplifyBorder, SplatDepthRule,
    TEMPLATE_DEPTH_SAMPLES, TEMPLATE_SMOOTHING, TsdfAnchor, VertexColors,
};
use crate::error::PipelineError;
use crate::opacity::{median_depth_views, opacity_gaussians, opacity_rig};
use crate::records::{Resolved, SimplifyFrame};

/// One deformed frame, as every mesher sees it.
#[derive(Clone, Copy, Debug)]
pub struct FrameInput<'a> {
    /// Animation frame index.
    pub frame: usize,
    /// Deformed template vertices.
    pub positions: &'a [DVec3],
    /// Deformed means of the Gaussians the point methods use ([`crate::Visibility`]).
    pub means: &'a [Vec3],
    /// The whole deformed (world-space) Gaussian set; present when the tsdf method runs.
    pub world: Option<&'a GaussianSet>,
}

/// One method's mesh of one frame.
#[derive(Clone, Debug)]
pub struct MethodOutput {
    /// The mesh.
    pub mesh: TriMesh,
    /// Wall time of the method on this frame, milliseconds (rendering included for tsdf).
    pub ms: f64,
    /// Of which rendering depth maps (tsdf only), milliseconds.
    pub render_ms: Option<f64>,
    /// What the incremental update did (delaunay only).
    pub delaunay: Option<FrameStats>,
    /// What decimation cost (`--faces`, `--simplify-error`; set by the finishing step).
    pub simplify: Option<SimplifyFrame>,
}

/// Mean distance from each point to its nearest other point (0 for a single point or only
/// duplicates); `None` when the points cannot be indexed (none, or non-finite coordinates).
#[must_use]
pub fn mean_spacing(points: &[Vec3]) -> Option<f64> {
    let index = PointIndex::new(points).ok()?;
    let near = index.k_nearest_batch(points, 2).ok()?;
    let sum: f64 = near
        .iter()
        .map(|n| n.iter().map(|x| x.distance).fold(0.0, f64::max))
        .sum();
    Some(sum / points.len().max(1) as f64)
}

/// Method `method`'s parameters as the report records them (`voxel`, `views`, `alpha`, ...,
/// and every method's `faces` or `simplify_error`, `simplify_lock_border` and
/// `vertex_colors`; flags as 0 or 1).
#[must_use]
pub fn parameters(
    method: Method,
    o: &ExtractOptions,
    resolved: &Resolved,
) -> BTreeMap<String, f64> {
    let mut parameters = BTreeMap::new();
    match method {
        Method::Tsdf => {
            parameters.insert("voxel".to_owned(), resolved.voxel);
            parameters.insert("views".to_owned(), o.tsdf.views as f64);
            parameters.insert("resolution".to_owned(), f64::from(o.tsdf.resolution));
            parameters.insert(
                "median_depth".to_owned(),
                f64::from(u8::from(o.tsdf.depth == DepthKind::Median)),
            );
            parameters.insert(
                "ray_depth".to_owned(),
                f64::from(u8::from(o.tsdf.splat_depth == SplatDepthRule::Ray)),
            );
            parameters.insert("colors".to_owned(), f64::from(u8::from(o.tsdf.colors)));
            parameters.insert("alpha_cut".to_owned(), f64::from(o.tsdf.alpha_cut));
            parameters.insert("front_alpha".to_owned(), f64::from(o.tsdf.front_alpha));
            parameters.insert(
                "anchored".to_owned(),
                f64::from(u8::from(o.tsdf.anchor == TsdfAnchor::Rigid)),
            );
        }
        Method::Delaunay => {
            parameters.insert("rebuild_every".to_owned(), o.delaunay.rebuild_every as f64);
            parameters.insert(
                "auto_rebuild".to_owned(),
                f64::from(u8::from(!o.delaunay.no_auto_rebuild)),
            );
            parameters.insert("hop_threshold".to_owned(), o.delaunay.hop_threshold);
        }
        Method::Alpha => {
            parameters.insert("alpha".to_owned(), resolved.alpha);
            let search = o.alpha.alpha.is_none() && o.alpha.rule.surface().is_some();
            parameters.insert(
                "alpha_complex".to_owned(),
                f64::from(u8::from(o.alpha.rule.surface().is_some())),
            );
            parameters.insert(
                "alpha_solid".to_owned(),
                f64::from(u8::from(o.alpha.rule == AlphaRule::Solid)),
            );
            if search {
                parameters.insert(
                    "alpha_ceiling".to_owned(),
                    DEFAULT_ALPHA_CEILING_SPACINGS * resolved.mean_spacing,
                );
                parameters.insert("alpha_pieces".to_owned(), o.alpha.pieces as f64);
            }
            parameters.insert("keep_clusters".to_owned(), o.alpha.keep_clusters as f64);
        }
        Method::Opacity => {
            parameters.insert("views".to_owned(), o.tsdf.views as f64);
            parameters.insert("resolution".to_owned(), f64::from(o.tsdf.resolution));
            parameters.insert(
                "bisection_steps".to_owned(),
                f64::from(OPACITY_BISECTION_STEPS),
            );
            let median = o.opacity.field != OpacityField::Gof;
            parameters.insert("median_field".to_owned(), f64::from(u8::from(median)));
            if median {
                let (rules, options) = median_rules(o.opacity.field, OpacityOptions::default());
                parameters.insert("depth_samples".to_owned(), f64::from(rules.sample_stride));
                parameters.insert(
                    "settle_rims".to_owned(),
                    f64::from(u8::from(options.settle_rims)),
                );
                parameters.insert("smoothing".to_owned(), f64::from(options.smoothing));
                parameters.insert("margin".to_owned(), f64::from(rules.margin));
                parameters.insert("carve_views".to_owned(), f64::from(rules.carve_views));
                parameters.insert("surface".to_owned(), f64::from(rules.surface));
            } else {
                parameters.insert("level".to_owned(), f64::from(OPACITY_LEVEL));
            }
            // The smallest share of the surface's area a kept piece has (0: every piece; 1:
            // only the largest).
            let share = match o.opacity.pieces {
                OpacityPieces::All => 0.0,
                OpacityPieces::Major => MAJOR_PIECE_FRACTION,
                OpacityPieces::Largest => 1.0,
            };
            parameters.insert("min_piece_share".to_owned(), share);
        }
    }
    if let Some(n) = o.finish.faces {
        parameters.insert("faces".to_owned(), n as f64);
    }
    if let (None, Some(e)) = (o.finish.faces, o.finish.simplify_error) {
        parameters.insert("simplify_error".to_owned(), e);
    }
    if o.finish.decimates() {
        parameters.insert(
            "simplify_lock_border".to_owned(),
            f64::from(u8::from(o.finish.simplify_border == SimplifyBorder::Locked)),
        );
    }
    parameters.insert(
        "vertex_colors".to_owned(),
        f64::from(u8::from(o.finish.vertex_colors != VertexColors::Off)),
    );
    parameters
}

impl Resolved {
    /// Resolves the defaults from the rest template and the rest-pose means, both in world
    /// space (the template as [`crate::input::read_template`] reads it: the scale of the
    /// frames, which [`crate::input::check_scale`] checks).
    ///
    /// # Errors
    /// [`PipelineError::BadOption`] for a given voxel or alpha that is not finite and
    /// positive, a voxel finer than `--max-voxels` allows, or a template without a
    /// finite extent.
    pub fn new(
        options: &ExtractOptions,
        rest: &TriMesh,
        rest_means: &[Vec3],
    ) -> Result<Self, PipelineError> {
        let Some((_, template_radius)) = bounding_sphere(rest.positions(), &[]) else {
            return Err(PipelineError::BadOption {
                name: "template",
                value: f64::NAN,
                expected: "a template with finite vertices",
            });
        };
        let spacing = mean_spacing(rest_means).unwrap_or(0.0);
        // Only duplicates (or one Gaussian): fall back to the template's scale.
        let spacing = if spacing > 0.0 {
            spacing
        } else {
            template_radius / DEFAULT_VOXELS_PER_RADIUS
        };
        let check = |name, v: Option<f64>, default: f64| match v {
            Some(v) if !(v.is_finite() && v > 0.0) => Err(PipelineError::BadOption {
                name,
                value: v,
                expected: "a finite positive length in scene units",
            }),
            Some(v) => Ok(v),
            None => Ok(default),
        };
        let voxel = check(
            "voxel",
            options.tsdf.voxel,
            default_voxel(template_radius, spacing),
        )?;
        // A voxel so fine that the template alone spans more than `--max-voxels` is refused
        // before any block is allocated (the default never is: it is at least R / 128).
        let across = 2.0 * template_radius / voxel;
        if across > options.limits.max_voxels as f64 {
            return Err(PipelineError::OverLimit {
                name: "voxel",
                value: voxel,
                limit: options.limits.max_voxels as f64,
                what: "voxels across the template's bounding sphere (a coarser --voxel gives fewer)",
                option: "max-voxels",
            });
        }
        Ok(Self {
            template_radius,
            mean_spacing: spacing,
            voxel,
            alpha: check(
                "alpha",
                options.alpha.alpha,
                match options.alpha.rule {
                    AlphaRule::Complex | AlphaRule::Solid => DEFAULT_ALPHA_FLOOR_SPACINGS * spacing,
                    AlphaRule::Open3d => DEFAULT_ALPHA_SPACINGS * spacing,
                },
            )?,
        })
    }
}

/// The default TSDF voxel: the Gaussians' mean nearest-neighbour `spacing` (depth rendered
/// from Gaussians holds no detail finer than their spacing, and a finer grid follows the
/// rendered discs), clamped to `template_radius` / [`DEFAULT_VOXELS_PER_RADIUS`] ..=
/// `template_radius` / [`COARSEST_VOXELS_PER_RADIUS`].
#[must_use]
pub fn default_voxel(template_radius: f64, spacing: f64) -> f64 {
    let finest = template_radius / DEFAULT_VOXELS_PER_RADIUS;
    let coarsest = template_radius / COARSEST_VOXELS_PER_RADIUS;
    spacing.max(finest).min(coarsest)
}

/// The alpha method's mesh of `means`: the alpha complex at the smallest α of `search`, or
/// at `alpha` by `rule`.
fn alpha_mesh(
    means: &[Vec3],
    alpha: f64,
    rule: AlphaRule,
    search: Option<&AlphaSearch>,
) -> Result<AlphaShape, trisplat_extract::alpha_shape::AlphaError> {
    match rule.surface() {
        None => alpha_shape(means, alpha),
        Some(surface) => {
            let delaunay = Delaunay3d::new(means)?;
            let complex = AlphaComplex::new(&delaunay);
            let alpha = match search {
                Some(s) => smallest_connected_alpha(&complex, s)?.alpha,
                None => alpha,
            };
            complex.shape(alpha, surface)
        }
    }
}

/// Why [`rendered_depth`] failed.
#[derive(Debug, thiserror::Error)]
pub enum RenderedDepthError {
    /// The renderer failed (or returned no depth).
    #[error("{0}")]
    Render(RenderError),
    /// The rendered depth does not make a depth image of the camera's size.
    #[error("{0}")]
    Image(TsdfError),
}

/// How [`rendered_depth`] turns a render into a depth map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthRules {
    /// Which depth of the render.
    pub kind: DepthKind,
    /// Each splat's depth over its footprint.
    pub splat: SplatDepthRule,
    /// Pixels whose rendered alpha is below this carry no depth (0 < cut <= 1).
    pub alpha_cut: f32,
    /// When positive, each depth map carries the front depth at this alpha
    /// ([`DepthImage::with_front`]): free space ends where the alpha first reaches it.
    pub front_alpha: f32,
}

impl Default for DepthRules {
    fn default() -> Self {
        Self {
            kind: DepthKind::default(),
            splat: SplatDepthRule::default(),
            alpha_cut: RENDERED_ALPHA_MIN,
            front_alpha: DEFAULT_FRONT_ALPHA,
        }
    }
}

/// The depth of `rules.kind` of world-space Gaussians seen by `camera` (3DGS splatting,
/// gsplat's rules, each splat's depth over its footprint by `rules.splat`), 0 (no surface)
/// where the rendered alpha is below `rules.alpha_cut`: the depth maps `trisplat tsdf
/// --gaussians` and the pipeline's tsdf method fuse.
///
/// # Errors
/// [`RenderedDepthError`].
pub fn rendered_depth(
    world: &GaussianSet,
    camera: &Camera,
    rules: &DepthRules,
) -> Result<DepthImage, RenderedDepthError> {
    Ok(rendered_view(world, camera, rules, false)?.0)
}

/// [`rendered_depth`], and `with_color` the rendered colour where there is depth: the
/// alpha-composited RGB (SH evaluated toward the camera) divided by the alpha, so that a
/// half-transparent rim keeps its colour instead of fading to the background.
///
/// # Errors
/// [`RenderedDepthError`].
pub fn rendered_view(
    world: &GaussianSet,
    camera: &Camera,
    rules: &DepthRules,
    with_color: bool,
) -> Result<(DepthImage, Option<ColorImage>), RenderedDepthError> {
    let (kind, cut) = (rules.kind, rules.alpha_cut);
    let options = RenderOptions {
        outputs: Outputs {
            rgb: with_color,
            alpha: true,
            depth: kind == DepthKind::Expected,
            median_depth: kind == DepthKind::Median,
            normal: false,
        },
        splat_depth: rules.splat.into(),
        ..RenderOptions::default()
    };
    if kind == DepthKind::Front && (rules.front_alpha.is_nan() || rules.front_alpha <= 0.0) {
        return Err(RenderedDepthError::Render(RenderError::BadFrontAlpha(
            rules.front_alpha,
        )));
    }
    let mut out = if rules.front_alpha > 0.0 {
        render_front(world, camera, &options, rules.front_alpha)
    } else {
        render(world, camera, &options)
    }
    .map_err(RenderedDepthError::Render)?;
    let depth = match kind {
        DepthKind::Expected => out.images.depth,
        DepthKind::Median => out.images.median_depth,
        DepthKind::Front => out.images.front_depth.take(),
    };
    let (Some(mut depth), Some(alpha)) = (depth, out.images.alpha) else {
        // Both were asked for: only a renderer that refused the set returns neither.
        return Err(RenderedDepthError::Render(RenderError::LocalParameters));
    };
    for (d, a) in depth.iter_mut().zip(&alpha) {
        if *a < cut {
            *d = 0.0;
        }
    }
    let color = match (with_color, out.images.rgb) {
        (false, _) => None,
        (true, Some(rgb)) => {
            let colors: Vec<[f32; 3]> = rgb
                .chunks_exact(3)
                .zip(&alpha)
                .map(|(c, &a)| {
                    if a >= cut {
                        [0, 1, 2].map(|k| (c[k] / a).clamp(0.0, 1.0))
                    } else {
                        [0.0; 3]
                    }
                })
                .collect();
            Some(
                ColorImage::try_new(camera.width, camera.height, colors)
                    .map_err(RenderedDepthError::Image)?,
            )
        }
        (true, None) => return Err(RenderedDepthError::Render(RenderError::LocalParameters)),
    };
    let mut depth = DepthImage::try_new(camera.width, camera.height, depth)
        .map_err(RenderedDepthError::Image)?;
    if let Some(front) = out.images.front_depth {
        depth = depth.with_front(front).map_err(RenderedDepthError::Image)?;
    }
    Ok((depth, color))
}

/// TSDF mesher settings.
#[derive(Clone, Debug)]
pub struct TsdfMesher {
    voxel: f64,
    views: usize,
    resolution: u32,
    depth: DepthRules,
    colors: bool,
    /// The rig in the rest template's frame (`--tsdf-anchor rigid`, [`crate::anchor`]);
    /// `None`: in world space around each frame.
    anchored: Option<AnchoredRig>,
}

impl TsdfMesher {
    fn mesh(&self, input: &FrameInput<'_>) -> Result<MethodOutput, PipelineError> {
        let start = Instant::now();
        let frame = input.frame;
        let Some(world) = input.world else {
            return Err(PipelineError::Internal {
                what: "the tsdf method was given no deformed Gaussian set",
            });
        };
        let Some((center, radius)) = bounding_sphere(input.positions, world.means()) else {
            return Ok(MethodOutput {
                mesh: TriMesh::default(),
                ms: start.elapsed().as_secs_f64() * 1e3,
                render_ms: Some(0.0),
                delaunay: None,
                simplify: None,
            });
        };
        let cameras_error = |source| PipelineError::Cameras {
            frame,
            cause: source,
        };
        // `cameras` fuse (anchor frame), `seen_by` render (world); `motion` maps the first
        // to the second and the fused mesh back.
        let (cameras, seen_by, motion) = match &self.anchored {
            Some(anchored) => {
                let anchor = anchored
                    .frame(
                        input.positions,
                        world.means(),
                        self.views,
                        self.resolution,
                        DEFAULT_FOV_DEG,
                    )
                    .map_err(cameras_error)?;
                let seen_by = anchor
                    .cameras
                    .iter()
                    .map(|c| anchor.motion.camera(c))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(cameras_error)?;
                (anchor.cameras, seen_by, Some(anchor.motion))
            }
            None => {
                let cameras = sphere_rig(
                    center,
                    radius,
                    self.views,
                    (self.resolution, self.resolution),
                    DEFAULT_FOV_DEG,
                )
                .map_err(cameras_error)?;
                (cameras.clone(), cameras, None)
            }
        };
        let mut depths = Vec::with_capacity(cameras.len());
        let mut colors = Vec::with_capacity(if self.colors { cameras.len() } else { 0 });
        for camera in &seen_by {
            let (image, color) =
                rendered_view(world, camera, &self.depth, self.colors).map_err(|e| match e {
                    RenderedDepthError::Render(source) => PipelineError::Render {
                        frame,
                        camera: camera.name.clone(),
                        cause: source,
                    },
                    RenderedDepthError::Image(source) => PipelineError::Tsdf {
                        frame,
                        cause: source,
                    },
                })?;
            depths.push(image);
            colors.extend(color);
        }
        let render_ms = start.elapsed().as_secs_f64() * 1e3;
        let options = TsdfOptions {
            voxel: Some(self.voxel),
            ..TsdfOptions::default()
        };
        let fused = fuse(
            &cameras,
            &depths,
            self.colors.then_some(&colors[..]),
            &options,
        )
        .map_err(|source| PipelineError::Tsdf {
            frame,
            cause: source,
        })?;
        let mesh = match motion {
            Some(motion) => motion.mesh(fused.mesh),
            None => fused.mesh,
        };
        Ok(MethodOutput {
            mesh,
            ms: start.elapsed().as_secs_f64() * 1e3,
            render_ms: Some(render_ms),
            delaunay: None,
            simplify: None,
        })
    }
}

/// A method with its state across frames.
#[derive(Debug)]
pub enum Mesher {
    /// Render + fuse.
    Tsdf(TsdfMesher),
    /// Incremental Delaunay (keeps its triangulation between frames).
    Delaunay(Box<IncrementalDelaunay>),
    /// Alpha shape at this radius (or the smallest α of `search`), keeping the edge-connected
    /// pieces at least as large as the `keep_clusters`-th largest (0: all).
    Alpha {
        /// Circumradius bound (the fixed α).
        alpha: f64,
        /// Which triangles form the mesh.
        rule: AlphaRule,
        /// The per-frame search of α (complex rule without a fixed α).
        search: Option<AlphaSearch>,
        /// Pieces kept (0: all).
        keep_clusters: usize,
    },
    /// The opacity field of every deformed Gaussian from the tsdf's rig: `views` cameras of
    /// `resolution`² pixels around the frame's Gaussians and their 3-sigma boxes.
    Opacity {
        /// Views of the rig.
        views: usize,
        /// Pixels across each view.
        resolution: u32,
        /// Whether vertices get the field's composited colours (not with
        /// `--vertex-colors off`).
        colors: bool,
        /// The field (`--opacity-field`).
        field: OpacityField,
        /// The pieces kept (`--opacity-pieces`).
        keep: KeepPieces,
        /// The tetrahedralisation carried from frame to frame when `OpacityOptions::carry` asks
        /// for it (off by default: on LAM a repair costs more than a rebuild, so every frame
        /// is rebuilt); equal to a rebuild either way.
        track: Box<OpacityTrack>,
    },
}

impl Mesher {
    /// A mesher for `method` on the rest template `rest` and the Gaussians' rest-pose means
    /// `rest_means` (deformed once by the caller; the point methods' kept means, or every
    /// Gaussian's for tsdf, whose anchored rig frames them).
    /// `first_frame` only labels errors.
    ///
    /// # Errors
    /// [`PipelineError::Delaunay`] when the incremental mesher cannot be built.
    pub fn new(
        method: Method,
        options: &ExtractOptions,
        resolved: &Resolved,
        rest: &TriMesh,
        rest_means: &[Vec3],
        first_frame: usize,
    ) -> Result<Self, PipelineError> {
        Ok(match method {
            Method::Tsdf => Self::Tsdf(TsdfMesher {
                voxel: resolved.voxel,
                views: options.tsdf.views,
                resolution: options.tsdf.resolution,
                depth: DepthRules {
                    kind: options.tsdf.depth,
                    splat: options.tsdf.splat_depth,
                    alpha_cut: options.tsdf.alpha_cut,
                    front_alpha: options.tsdf.front_alpha,
                },
                colors: options.tsdf.colors,
                anchored: match options.tsdf.anchor {
                    TsdfAnchor::Rigid => AnchoredRig::new(rest.positions(), rest_means),
                    TsdfAnchor::World => None,
                },
            }),
            Method::Delaunay => {
                let d_options = DelaunayOptions {
                    rebuild_every: options.delaunay.rebuild_every,
                    auto_rebuild: !options.delaunay.no_auto_rebuild,
                    hop_threshold: options.delaunay.hop_threshold,
                    ..DelaunayOptions::default()
                };
                let d =
                    IncrementalDelaunay::new(rest, rest_means, d_options).map_err(|source| {
                        PipelineError::Delaunay {
                            frame: first_frame,
                            cause: source,
                        }
                    })?;
                Self::Delaunay(Box::new(d))
            }
            Method::Alpha => Self::Alpha {
                alpha: resolved.alpha,
                rule: options.alpha.rule,
                search: options
                    .alpha
                    .rule
                    .surface()
                    .filter(|_| options.alpha.alpha.is_none())
                    .map(|surface| AlphaSearch {
                        floor: resolved.alpha,
                        ceiling: (DEFAULT_ALPHA_CEILING_SPACINGS * resolved.mean_spacing)
                            .max(resolved.alpha),
                        steps_per_doubling: ALPHA_STEPS_PER_DOUBLING,
                        max_pieces: options.alpha.pieces,
                        surface,
                    }),
                keep_clusters: options.alpha.keep_clusters,
            },
            Method::Opacity => Self::Opacity {
                views: options.tsdf.views,
                resolution: options.tsdf.resolution,
                colors: options.finish.vertex_colors != VertexColors::Off,
                field: options.opacity.field,
                keep: match options.opacity.pieces {
                    OpacityPieces::All => KeepPieces::All,
                    OpacityPieces::Major => KeepPieces::Major,
                    OpacityPieces::Largest => KeepPieces::Largest,
                },
                track: Box::default(),
            },
        })
    }

    /// Meshes one frame.
    ///
    /// # Errors
    /// The method's failure, naming the frame.
    pub fn mesh(&mut self, input: &FrameInput<'_>) -> Result<MethodOutput, PipelineError> {
        let frame = input.frame;
        match self {
            Self::Tsdf(t) => t.mesh(input),
            Self::Delaunay(d) => {
                let start = Instant::now();
                let stats = d.update(input.positions, input.means).map_err(|source| {
                    PipelineError::Delaunay {
                        frame,
                        cause: source,
                    }
                })?;
                let mesh = d.mesh();
                Ok(MethodOutput {
                    mesh,
                    ms: start.elapsed().as_secs_f64() * 1e3,
                    render_ms: None,
                    delaunay: Some(stats),
                    simplify: None,
                })
            }
            Self::Alpha {
                alpha,
                rule,
                search,
                keep_clusters,
            } => {
                let start = Instant::now();
                let shape =
                    alpha_mesh(input.means, *alpha, *rule, search.as_ref()).map_err(|source| {
                        PipelineError::Alpha {
                            frame,
                            cause: source,
                        }
                    })?;
                Ok(MethodOutput {
                    mesh: keep_largest_clusters(&shape.mesh, *keep_clusters),
                    ms: start.elapsed().as_secs_f64() * 1e3,
                    render_ms: None,
                    delaunay: None,
                    simplify: None,
                })
            }
            Self::Opacity {
                views,
                resolution,
                colors,
                field,
                keep,
                track,
            } => {
                let start = Instant::now();
                let world = input.world.ok_or(PipelineError::Internal {
                    what: "the opacity method without the frame's deformed Gaussians",
                })?;
                let cameras = opacity_rig(world, *views, *resolution)?;
                let options = OpacityOptions {
                    colors: *colors,
                    keep: *keep,
                    ..OpacityOptions::default()
                };
                let gaussians = opacity_gaussians(world);
                let (meshed, render_ms) = match field {
                    OpacityField::Gof => (
                        opacity_mesh_tracked(&gaussians, &cameras, &options, track),
                        None,
                    ),
                    OpacityField::Median | OpacityField::Template => {
                        let maps = median_depth_views(world, &cameras, *colors, frame)?;
                        let render_ms = start.elapsed().as_secs_f64() * 1e3;
                        let (rules, options) = median_rules(*field, options);
                        let meshed =
                            median_depth_mesh(&gaussians, &maps, rules, &options, Some(track));
                        (meshed, Some(render_ms))
                    }
                };
                let meshed = meshed.map_err(|cause| PipelineError::Opacity { frame, cause })?;
                Ok(MethodOutput {
                    mesh: meshed.mesh,
                    ms: start.elapsed().as_secs_f64() * 1e3,
                    render_ms,
                    delaunay: None,
                    simplify: None,
                })
            }
        }
    }
}

/// The median field's rules and options for `field` (`median` or `template`, config/opacity.rs).
fn median_rules(field: OpacityField, options: OpacityOptions) -> (MedianRules, OpacityOptions) {
    if field == OpacityField::Template {
        (
            MedianRules {
                sample_stride: TEMPLATE_DEPTH_SAMPLES,
                ..MedianRules::default()
            },
            OpacityOptions {
                settle_rims: true,
                smoothing: TEMPLATE_SMOOTHING,
                ..options
            },
        )
    } else {
        (MedianRules::default(), options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two walls of wide flat Gaussians facing a camera on the z axis: a half-transparent one
    /// (opacity 0.6) at z = 1 in front of an opaque one at z = 2.
    fn two_walls() -> (GaussianSet, Camera) {
        two_walls_with(0.6)
    }

    /// [`two_walls`] with the front wall of opacity `front`.
    fn two_walls_with(front: f32) -> (GaussianSet, Camera) {
        use trisplat_splat::{GaussianParts, ParameterSpace, ScaleDims};
        let logit = |o: f32| (o / (1.0 - o)).ln();
        let mut parts = GaussianParts {
            means: Vec::new(),
            log_scales: Vec::new(),
            scale_dims: ScaleDims::Three,
            rotations: Vec::new(),
            opacity_logits: Vec::new(),
            sh_degree: 0,
            sh: Vec::new(),
            binding: None,
            material: None,
            space: ParameterSpace::World,
            extras: Vec::new(),
            property_order: None,
        };
        for (z, opacity) in [(1.0, front), (2.0, 0.999)] {
            parts.means.push(Vec3::new(0.0, 0.0, z));
            parts
                .log_scales
                .push(Vec3::new(5f32.ln(), 5f32.ln(), 1e-3f32.ln()));
            parts.rotations.push([1.0, 0.0, 0.0, 0.0]);
            parts.opacity_logits.push(logit(opacity));
            parts.sh.extend([0.0; 3]);
        }
        let set = GaussianSet::try_new(parts).expect("valid set");
        let camera = Camera::look_at("c", DVec3::ZERO, DVec3::Z, DVec3::NEG_Y, (16, 16), 40.0)
            .expect("camera");
        (set, camera)
    }

    #[test]
    fn median_depth_is_the_first_surface_expected_depth_a_blend() {
        let (set, camera) = two_walls();
        let centre = |kind| {
            let rules = DepthRules {
                kind,
                splat: SplatDepthRule::Mean,
                ..DepthRules::default()
            };
            let d = rendered_depth(&set, &camera, &rules).expect("renders");
            d.data()[8 * 16 + 8]
        };
        // Accumulated alpha passes 1/2 at the front wall.
        assert!((centre(DepthKind::Median) - 1.0).abs() < 1e-3);
        // 0.6 of the weight at z = 1, 0.4 at z = 2, normalised by the alpha (≈ 1).
        let expected = centre(DepthKind::Expected);
        assert!((expected - 1.4).abs() < 1e-2, "{expected}");
    }

    #[test]
    fn front_depth_is_where_the_alpha_first_reaches_the_front_alpha() {
        // A wall of opacity 0.3 in front of an opaque one: the alpha passes 1/2 only at the
        // back wall, 0.2 already at the front one.
        let (set, camera) = two_walls_with(0.3);
        let rules = |kind, front_alpha| DepthRules {
            kind,
            splat: SplatDepthRule::Mean,
            alpha_cut: 0.5,
            front_alpha,
        };
        let centre = |r: &DepthRules| rendered_depth(&set, &camera, r).expect("renders");
        let median = centre(&rules(DepthKind::Median, 0.2));
        assert!((median.data()[8 * 16 + 8] - 2.0).abs() < 1e-3);
        // The median depth map carries the front depth for fusion's free space.
        let front = median.front().expect("front depths")[8 * 16 + 8];
        assert!((front - 1.0).abs() < 1e-3, "{front}");
        let fused = centre(&rules(DepthKind::Front, 0.2));
        assert!((fused.data()[8 * 16 + 8] - 1.0).abs() < 1e-3);
        // Above the front wall's alpha the front depth is the back wall's.
        let deep = centre(&rules(DepthKind::Front, 0.4));
        assert!((deep.data()[8 * 16 + 8] - 2.0).abs() < 1e-3);
        // Without a front alpha the front kind is refused, and median maps carry none.
        assert!(rendered_depth(&set, &camera, &rules(DepthKind::Front, 0.0)).is_err());
        let plain = centre(&rules(DepthKind::Median, 0.0));
        assert!(plain.front().is_none());
    }

    #[test]
    fn alpha_keeps_its_largest_pieces_on_request() {
        // A unit cube's corners (12 boundary triangles) and a far tetrahedron (4).
        let mut means: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        means.extend(
            [
                [10., 10., 10.],
                [11., 10., 10.],
                [10., 11., 10.],
                [10., 10., 11.],
            ]
            .map(Vec3::from),
        );
        let input = FrameInput {
            frame: 0,
            positions: &[],
            means: &means,
            world: None,
        };
        for (keep, triangles) in [(0, 16), (1, 12), (2, 16)] {
            let mut mesher = Mesher::Alpha {
                alpha: 2.0,
                rule: AlphaRule::Open3d,
                search: None,
                keep_clusters: keep,
            };
            let out = mesher.mesh(&input).expect("alpha shape");
            assert_eq!(out.mesh.triangle_count(), triangles, "keep {keep}");
        }
    }

    /// Isotropic Gaussians on an ellipsoid (a Fibonacci lattice, vertex `i` the mean of
    /// Gaussian `i`), moved by `motion`.
    fn ellipsoid(motion: &crate::anchor::Rigid) -> (Vec<DVec3>, GaussianSet) {
        use trisplat_splat::{GaussianParts, ParameterSpace, ScaleDims};
        let n = 1500;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let rest: Vec<DVec3> = (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - y * y).sqrt();
                let phi = golden * i as f64;
                DVec3::new(r * phi.cos(), 0.8 * y, 0.6 * r * phi.sin())
            })
            .collect();
        let moved: Vec<DVec3> = rest.iter().map(|&p| motion.apply(p)).collect();
        let parts = GaussianParts {
            means: moved.iter().map(|p| p.as_vec3()).collect(),
            log_scales: vec![Vec3::splat(0.05f32.ln()); n],
            scale_dims: ScaleDims::Three,
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacity_logits: vec![4.0; n],
            sh_degree: 0,
            sh: vec![0.0; 3 * n],
            binding: None,
            material: None,
            space: ParameterSpace::World,
            extras: Vec::new(),
            property_order: None,
        };
        (moved, GaussianSet::try_new(parts).expect("valid set"))
    }

    /// Largest distance from a vertex of `a` to the nearest vertex of `b` (brute force).
    fn farthest_nearest(a: &TriMesh, b: &TriMesh) -> f64 {
        a.positions()
            .iter()
            .map(|p| {
                b.positions()
                    .iter()
                    .map(|q| (*p - *q).length_squared())
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
            .sqrt()
    }

    #[test]
    fn an_anchored_tsdf_moves_with_a_rigidly_moving_surface() {
        use crate::anchor::Rigid;
        use glam::{DMat3, DQuat};
        let still = Rigid::IDENTITY;
        // A turn and a shift that is no multiple of the voxel.
        let turn = Rigid {
            rotation: DMat3::from_quat(DQuat::from_axis_angle(
                DVec3::new(0.2, 1.0, 0.3).normalize(),
                0.45,
            )),
            translation: DVec3::new(0.0371, -0.0213, 0.0157),
        };
        let (rest, _) = ellipsoid(&still);
        let mesh = |mesher: &TsdfMesher, motion: &Rigid| {
            let (positions, world) = ellipsoid(motion);
            let input = FrameInput {
                frame: 0,
                positions: &positions,
                means: world.means(),
                world: Some(&world),
            };
            mesher.mesh(&input).expect("tsdf").mesh
        };
        let voxel = 0.05;
        let rigid = TsdfMesher {
            voxel,
            views: 8,
            resolution: 64,
            depth: DepthRules::default(),
            colors: false,
            anchored: crate::anchor::AnchoredRig::new(&rest, &[]),
        };
        let world = TsdfMesher {
            anchored: None,
            ..rigid.clone()
        };
        for (mesher, anchored) in [(&rigid, true), (&world, false)] {
            let key = mesh(mesher, &still);
            let own = mesh(mesher, &turn);
            assert!(key.vertex_count() > 500, "{}", key.vertex_count());
            let carried = turn.mesh(key);
            let gap = farthest_nearest(&carried, &own).max(farthest_nearest(&own, &carried));
            if anchored {
                // The same sampling, moved: equal to the renderer's f32 rounding.
                assert_eq!(carried.vertex_count(), own.vertex_count());
                assert!(gap < 1e-3 * voxel, "anchored: {gap}");
            } else {
                // Resampled on the world grid: a new mesh, a sizeable part of a voxel away.
                assert!(gap > 0.05 * voxel, "world: {gap}");
            }
        }
    }

    #[test]
    fn spacing_of_a_grid() {
        let pts: Vec<Vec3> = (0..10)
            .flat_map(|i| (0..10).map(move |j| Vec3::new(i as f32 * 0.5, j as f32 * 0.5, 0.0)))
            .collect();
        let s = mean_spacing(&pts).expect("finite");
        assert!((s - 0.5).abs() < 1e-6, "{s}");
        assert_eq!(mean_spacing(&[]), None);
    }
}
