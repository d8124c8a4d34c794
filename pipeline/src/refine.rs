//! Surface-guided re-initialisation of a bound avatar (VGA/GVA's "Re-Gaussian" step;
//! `trisplat refine`, docs/conventions.md §4).
//!
//! One round, on a set bound to a template (local parameters, a triangle per Gaussian):
//!
//! 1. **bake**: the set deformed at the template's rest: the world-space Gaussian centres;
//! 2. **alpha**: the alpha shape of the centres (`extract::alpha_shape`, Open3D's definition)
//!    at `alpha` (default [`crate::config::DEFAULT_ALPHA_SPACINGS`] × the centres' mean
//!    nearest-neighbour spacing, as the main job's `alpha` method), optionally only its largest
//!    edge-connected pieces;
//! 3. **smooth**: that surface smoothed (`geometry::smoothing`, default Laplacian, 10
//!    iterations, λ 0.5);
//! 4. **sample**: `samples` points on the smoothed surface (`geometry::sampling`, default
//!    area-uniform, seeded). By default as many as there are Gaussians, less the old Gaussians
//!    step 6 keeps to refill emptied triangles (counted on a first draw, then drawn again), so
//!    the count grows only by what the second draw empties;
//! 5. **inherit**: each point becomes a Gaussian that copies every attribute of the old
//!    Gaussian nearest to it (world-space rotation, scales, opacity, SH, extra properties), at
//!    the point;
//! 6. **bind**: the new Gaussians bound to template triangles with the binding code
//!    (`splat::attach_to_triangles`): by default the triangle of the old Gaussian they
//!    copy ([`Rebind::Inherit`], so LAM's per-vertex Gaussians stay with their part of the
//!    mesh), or the nearest triangle ([`Rebind::Nearest`], as `bind --gaussians`). Binding
//!    inheritance: a triangle that had Gaussians and would be left without any keeps its first
//!    old Gaussian (counted as `refilled`);
//! 7. **prune** (optional): outlier and normal-consistency pruning of the new set in world
//!    space with the gate's form and thresholds ([`PruneCriteria`]; the seed's ε_o = 0.015,
//!    ε_n = 0.3, k = 5 by default), never emptying a triangle (`splat::prune`);
//! 8. **chamfer**: the Chamfer distance of the centres to the template's surface (surface
//!    mode of docs/conventions.md §8: centres to the exact surface, the template's area-uniform
//!    samples to the nearest centre).
//!
//! Each round's [`RoundReport`] gives the counts, the Chamfer before and after, and the time
//! of every stage. Random choices are seeded (round `r` samples with `seed + r`), so a run is
//! reproducible and does not depend on the thread count.

use std::time::Instant;

use glam::Vec3;
use trisplat_extract::alpha_shape::alpha_shape;
use trisplat_geometry::cleanup::keep_largest_clusters;
use trisplat_geometry::metrics::{MetricsOptions, Shape, evaluate};
use trisplat_geometry::sampling::{SampleOptions, sample, sample_uniform};
use trisplat_geometry::smoothing::{SmoothOptions, smooth};
use trisplat_geometry::spatial::{PointIndex, TriangleBvh};
use trisplat_geometry::topology::TriangleClusters;
use trisplat_geometry::{PointCloud, TriId, TriMesh};
use trisplat_splat::Convention;
use trisplat_splat::GaussianSet;
use trisplat_splat::attach_to_triangles;
use trisplat_splat::{
    DEFAULT_NEIGHBOURS, Gate, SEED_NORMAL, SEED_OUTLIER, TriangleCounts, normal_deviation_mask,
    normal_inconsistency_mask, outlier_mask, prune,
};
use trisplat_splat::{DeformMode, Deformer};

use crate::config::DEFAULT_ALPHA_SPACINGS;
use crate::methods::mean_spacing;

/// Default number of rounds.
pub const DEFAULT_ROUNDS: usize = 1;

/// Default number of template samples of the Chamfer distance (the main job's metric samples).
pub const DEFAULT_CHAMFER_SAMPLES: usize = crate::config::DEFAULT_SAMPLES;

/// Seed of the template samples of the Chamfer distance (fixed, so rounds compare).
const CHAMFER_SEED: u64 = 0;

/// How the new Gaussians choose their triangle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Rebind {
    /// The triangle of the old Gaussian each new one copies (binding inheritance).
    #[default]
    Inherit,
    /// The template triangle nearest the new centre (exact closest point), as `bind --gaussians`.
    Nearest,
}

/// The pruning stage: the gate's form, its thresholds (`None`: that criterion is off) and the
/// neighbour count.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PruneCriteria {
    /// [`Gate::Seed`]: `normal` is ε_n on the mean deviation `1 - |cos|`; [`Gate::Stable`]:
    /// `normal` is C on the mean `|cos|` (pruned below). `outlier` is the same in both.
    pub gate: Gate,
    /// Outlier threshold on the mean distance to the `k` nearest other Gaussians (scene units).
    pub outlier: Option<f64>,
    /// Normal-consistency threshold (see `gate`).
    pub normal: Option<f64>,
    /// Neighbours of both criteria.
    pub k: usize,
}

impl PruneCriteria {
    /// The seed's (GSDHuman's) pruning: ε_o = 0.015, ε_n = 0.3, k = 5.
    #[must_use]
    pub fn seed() -> Self {
        Self {
            gate: Gate::Seed,
            outlier: Some(SEED_OUTLIER),
            normal: Some(SEED_NORMAL),
            k: DEFAULT_NEIGHBOURS,
        }
    }

    /// No pruning.
    #[must_use]
    pub fn none() -> Self {
        Self {
            gate: Gate::Stable,
            outlier: None,
            normal: None,
            k: DEFAULT_NEIGHBOURS,
        }
    }

    fn is_active(&self) -> bool {
        self.outlier.is_some() || self.normal.is_some()
    }
}

/// Options of [`refine`]; [`Default`] gives the seed's defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineOptions {
    /// Rounds of re-initialisation ([`DEFAULT_ROUNDS`]).
    pub rounds: usize,
    /// Alpha-shape radius in scene units; `None`: `alpha_spacings` × the mean spacing.
    pub alpha: Option<f64>,
    /// Alpha radius in mean nearest-neighbour spacings of the centres when `alpha` is `None`.
    pub alpha_spacings: f64,
    /// Keep the alpha shape's pieces at least as large as the K-th largest (0: all).
    pub keep_clusters: usize,
    /// Smoothing of the alpha shape.
    pub smooth: SmoothOptions,
    /// Points sampled on the smoothed surface; `None`: the current number of Gaussians less
    /// the refilled ones (see the module docs).
    pub samples: Option<usize>,
    /// Sampling method and seed (round `r` uses `seed + r`).
    pub sample: SampleOptions,
    /// How new Gaussians choose their triangle.
    pub rebind: Rebind,
    /// The pruning stage.
    pub prune: PruneCriteria,
    /// The deformation mode the set is bound for (binding: GaussianAvatars frames; jacobian:
    /// SurFhead frames).
    pub mode: DeformMode,
    /// Template samples of the Chamfer distance ([`DEFAULT_CHAMFER_SAMPLES`]).
    pub chamfer_samples: usize,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            rounds: DEFAULT_ROUNDS,
            alpha: None,
            alpha_spacings: DEFAULT_ALPHA_SPACINGS,
            keep_clusters: 0,
            smooth: SmoothOptions::default(),
            samples: None,
            sample: SampleOptions::default(),
            rebind: Rebind::Inherit,
            prune: PruneCriteria::seed(),
            mode: DeformMode::Binding,
            chamfer_samples: DEFAULT_CHAMFER_SAMPLES,
        }
    }
}

/// The Chamfer distance of the Gaussian centres to the template (docs/conventions.md §8,
/// surface mode).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CentreChamfer {
    /// Mean distance from a centre to the template's surface.
    pub accuracy: f64,
    /// Mean distance from a template sample to the nearest centre.
    pub completeness: f64,
    /// (accuracy + completeness) / 2.
    pub chamfer_l1: f64,
}

/// Milliseconds of each stage of one round.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageMs {
    /// Deforming the set at the template's rest.
    pub bake: f64,
    /// The centres' spacing (for the default α), tetrahedralisation and boundary, pieces kept.
    pub alpha: f64,
    /// Smoothing the alpha shape.
    pub smooth: f64,
    /// Sampling the smoothed surface.
    pub sample: f64,
    /// Nearest old Gaussian of every sample, attributes copied.
    pub inherit: f64,
    /// Triangles chosen, emptied triangles refilled, local parameters.
    pub bind: f64,
    /// Outlier and normal-consistency masks and the prune.
    pub prune: f64,
    /// The Chamfer distance after the round.
    pub chamfer: f64,
}

/// What one round did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RoundReport {
    /// Round number, from 1.
    pub round: usize,
    /// Gaussians before the round.
    pub before: usize,
    /// Gaussians after the round.
    pub after: usize,
    /// The alpha radius used.
    pub alpha: f64,
    /// Vertices of the alpha shape (after keeping pieces).
    pub alpha_vertices: usize,
    /// Triangles of the alpha shape (after keeping pieces).
    pub alpha_triangles: usize,
    /// Edge-connected pieces of the alpha shape, and those kept.
    pub pieces: usize,
    /// Pieces kept (`keep_clusters`).
    pub kept_pieces: usize,
    /// Points sampled on the smoothed surface (new Gaussians).
    pub samples: usize,
    /// Old Gaussians kept so that no triangle is left empty.
    pub refilled: usize,
    /// Gaussians the pruning stage flagged.
    pub flagged: usize,
    /// Gaussians it removed.
    pub pruned: usize,
    /// Flagged Gaussians kept because their triangle would have been emptied.
    pub spared: usize,
    /// Triangles with at least one Gaussian after the round.
    pub covered_triangles: usize,
    /// Chamfer distance of the centres to the template before the round.
    pub chamfer_before: CentreChamfer,
    /// And after.
    pub chamfer_after: CentreChamfer,
    /// Milliseconds per stage.
    pub ms: StageMs,
    /// Milliseconds of the whole round (the stages plus bookkeeping).
    pub total_ms: f64,
}

/// The surfaces of one round, for callers that keep or show them.
#[derive(Clone, Copy, Debug)]
pub struct RoundSurfaces<'a> {
    /// The alpha shape of the centres (the pieces kept).
    pub alpha: &'a TriMesh,
    /// The same smoothed: the surface the new Gaussians were sampled on.
    pub smoothed: &'a TriMesh,
}

/// The refined set and the report of every round.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    /// The bound set after the last round.
    pub set: GaussianSet,
    /// One report per round.
    pub rounds: Vec<RoundReport>,
}

/// Errors of [`refine`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RefineError {
    /// An option out of its range.
    #[error("--{name} {value}: {expected}")]
    BadOption {
        /// The option's command-line name.
        name: &'static str,
        /// The value given.
        value: String,
        /// What is accepted.
        expected: &'static str,
    },
    /// The input set cannot be refined.
    #[error("{0}")]
    Input(String),
    /// A stage of a round failed.
    #[error("round {round}: {stage}: {message}")]
    Stage {
        /// Round number, from 1.
        round: usize,
        /// The stage (`bake`, `alpha`, `smooth`, `sample`, `inherit`, `bind`, `prune`,
        /// `chamfer`).
        stage: &'static str,
        /// What went wrong.
        message: String,
    },
}

/// New centres, the old Gaussian each copies, their triangles, and the old Gaussians kept to
/// refill triangles the new ones leave empty.
struct Placed {
    positions: Vec<Vec3>,
    sources: Vec<usize>,
    triangles: Vec<TriId>,
    refill: Vec<usize>,
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn check_options(o: &RefineOptions) -> Result<(), RefineError> {
    let bad = |name, value: f64, expected| RefineError::BadOption {
        name,
        value: value.to_string(),
        expected,
    };
    if let Some(a) = o.alpha
        && !(a.is_finite() && a > 0.0)
    {
        return Err(bad("alpha", a, "expected a positive radius"));
    }
    if !(o.alpha_spacings.is_finite() && o.alpha_spacings > 0.0) {
        return Err(bad(
            "alpha-spacings",
            o.alpha_spacings,
            "expected a positive number",
        ));
    }
    if o.samples == Some(0) {
        return Err(bad("samples", 0.0, "expected at least one point"));
    }
    if o.chamfer_samples == 0 {
        return Err(bad("chamfer-samples", 0.0, "expected at least one point"));
    }
    for (name, v) in [
        ("outlier-threshold", o.prune.outlier),
        ("normal-threshold", o.prune.normal),
    ] {
        if let Some(v) = v
            && !(v.is_finite() && v >= 0.0)
        {
            return Err(bad(name, v, "expected a non-negative number"));
        }
    }
    if o.prune.k == 0 {
        return Err(bad("neighbours", 0.0, "expected at least one neighbour"));
    }
    Ok(())
}

fn convention_of(mode: DeformMode) -> Convention {
    match mode {
        DeformMode::Binding => Convention::GaussianAvatars,
        DeformMode::Jacobian => Convention::SurfHead,
    }
}

/// The Chamfer distance of `centres` to the template (`samples` on it, `bvh` over it).
fn centre_chamfer(
    centres: &[Vec3],
    template: &TriMesh,
    samples: &PointCloud,
    bvh: &TriangleBvh,
) -> Result<CentreChamfer, String> {
    let cloud = PointCloud::try_new(centres.to_vec()).map_err(|e| e.to_string())?;
    let m = evaluate(
        Shape::points(&cloud),
        Shape::indexed_mesh(template, samples, bvh),
        &MetricsOptions {
            taus: Vec::new(),
            surface: true,
        },
    )
    .map_err(|e| e.to_string())?;
    Ok(CentreChamfer {
        accuracy: m.accuracy,
        completeness: m.completeness,
        chamfer_l1: m.chamfer_l1,
    })
}

/// Runs `options.rounds` rounds of surface-guided re-initialisation on `set`, bound to
/// `template` (see the module docs), calling `on_round` after each round with its report and
/// its surfaces.
///
/// # Errors
/// [`RefineError::BadOption`] for an option out of range; [`RefineError::Input`] for an empty
/// or unbound set, a binding past the template or a template without area;
/// [`RefineError::Stage`] naming the round and stage that failed (an empty alpha shape, a
/// smoothed surface without area, non-finite centres, ...).
pub fn refine(
    set: &GaussianSet,
    template: &TriMesh,
    options: &RefineOptions,
    mut on_round: impl FnMut(&RoundReport, &RoundSurfaces<'_>),
) -> Result<Refined, RefineError> {
    check_options(options)?;
    if set.is_empty() {
        return Err(RefineError::Input("the set has no Gaussians".into()));
    }
    if set.binding().is_none() {
        return Err(RefineError::Input(
            "the Gaussians are not bound to triangles (bind them with `trisplat bind` first)"
                .into(),
        ));
    }
    let triangle_count = template.triangle_count();
    TriangleCounts::from_set(set, triangle_count)
        .map_err(|e| RefineError::Input(format!("{e} (template triangles)")))?;
    let convention = convention_of(options.mode);
    let deformer = Deformer::new(template, options.mode);
    let bvh =
        TriangleBvh::new(template).map_err(|e| RefineError::Input(format!("template: {e}")))?;
    let template_samples = sample_uniform(template, options.chamfer_samples, CHAMFER_SEED);
    if template_samples.is_empty() {
        return Err(RefineError::Input("the template has no area".into()));
    }
    let mut current = set.clone();
    let mut chamfer_now: Option<CentreChamfer> = None;
    let mut reports = Vec::with_capacity(options.rounds);
    for round in 1..=options.rounds {
        let stage = |stage: &'static str| {
            move |message: String| RefineError::Stage {
                round,
                stage,
                message,
            }
        };
        let start = Instant::now();
        let mut ms = StageMs::default();

        // 1. bake
        let t = Instant::now();
        let world = deformer
            .deform(&current, template.positions())
            .map_err(|e| stage("bake")(e.to_string()))?;
        ms.bake = ms_since(t);
        let chamfer_before = match chamfer_now {
            Some(c) => c,
            None => {
                let t = Instant::now();
                let c = centre_chamfer(world.means(), template, &template_samples, &bvh)
                    .map_err(stage("chamfer"))?;
                ms.chamfer += ms_since(t);
                c
            }
        };

        // 2. alpha
        let t = Instant::now();
        let alpha = match options.alpha {
            Some(a) => a,
            None => {
                let spacing = mean_spacing(world.means()).unwrap_or(0.0);
                if !(spacing.is_finite() && spacing > 0.0) {
                    return Err(stage("alpha")(format!(
                        "the {} centres have no spacing (all coincident?); give --alpha",
                        world.len()
                    )));
                }
                options.alpha_spacings * spacing
            }
        };
        let shape = alpha_shape(world.means(), alpha).map_err(|e| stage("alpha")(e.to_string()))?;
        let pieces = TriangleClusters::of(&shape.mesh).count();
        let surface = keep_largest_clusters(&shape.mesh, options.keep_clusters);
        let kept_pieces = TriangleClusters::of(&surface).count();
        ms.alpha = ms_since(t);
        if surface.triangle_count() == 0 {
            return Err(stage("alpha")(format!(
                "the alpha shape of the {} centres at alpha {alpha} has no triangles (raise \
                 --alpha or --alpha-spacings)",
                world.len()
            )));
        }

        // 3. smooth
        let t = Instant::now();
        let smoothed =
            smooth(&surface, &options.smooth).map_err(|e| stage("smooth")(e.to_string()))?;
        ms.smooth = ms_since(t);

        // 4.-6. sample, inherit, bind. By default as many points as there are Gaussians less
        // the old ones kept to refill emptied triangles, so the count grows only by what the
        // second draw empties.
        let old_triangles = &current
            .binding()
            .ok_or_else(|| stage("bind")("the set lost its binding".into()))?
            .triangles;
        let index = PointIndex::new(world.means()).map_err(|e| stage("inherit")(e.to_string()))?;
        let sample_options = SampleOptions {
            seed: options.sample.seed.wrapping_add(round as u64),
            ..options.sample.clone()
        };
        let place = |n: usize, ms: &mut StageMs| -> Result<Placed, RefineError> {
            let t = Instant::now();
            let points = sample(&smoothed, n, &sample_options)
                .map_err(|e| stage("sample")(e.to_string()))?;
            ms.sample += ms_since(t);
            if points.is_empty() {
                return Err(stage("sample")(
                    "the smoothed surface has no area: no point could be sampled".into(),
                ));
            }
            let positions = points.points.positions().to_vec();
            let t = Instant::now();
            let sources: Vec<usize> = index
                .nearest_batch(&positions)
                .map_err(|e| stage("inherit")(e.to_string()))?
                .iter()
                .map(|m| m.index as usize)
                .collect();
            ms.inherit += ms_since(t);
            let t = Instant::now();
            let triangles: Vec<TriId> = match options.rebind {
                Rebind::Inherit => sources.iter().map(|&j| old_triangles[j]).collect(),
                Rebind::Nearest => bvh
                    .closest_points(&positions)
                    .map_err(|e| stage("bind")(e.to_string()))?
                    .iter()
                    .map(|c| TriId(c.triangle))
                    .collect(),
            };
            // Binding inheritance: every triangle that had a Gaussian keeps one.
            let mut covered = vec![false; triangle_count];
            for t in &triangles {
                covered[t.index()] = true;
            }
            let mut refill = Vec::new();
            for (j, t) in old_triangles.iter().enumerate() {
                if !covered[t.index()] {
                    covered[t.index()] = true;
                    refill.push(j);
                }
            }
            ms.bind += ms_since(t);
            Ok(Placed {
                positions,
                sources,
                triangles,
                refill,
            })
        };
        let mut placed = place(options.samples.unwrap_or(current.len()), &mut ms)?;
        if options.samples.is_none() && !placed.refill.is_empty() {
            let n = current.len().saturating_sub(placed.refill.len()).max(1);
            placed = place(n, &mut ms)?;
        }
        let t = Instant::now();
        let Placed {
            positions,
            mut sources,
            mut triangles,
            refill,
        } = placed;
        let new_count = sources.len();
        sources.extend_from_slice(&refill);
        triangles.extend(refill.iter().map(|&j| old_triangles[j]));
        let mut parts = world.select(&sources).into_parts();
        parts.means[..new_count].copy_from_slice(&positions);
        let new_world = GaussianSet::new_unchecked(parts);
        let bound = attach_to_triangles(&new_world, template, &triangles, convention)
            .map_err(|e| stage("bind")(e.to_string()))?;
        ms.bind += ms_since(t);

        // 7. prune
        let t = Instant::now();
        let (next, next_means, flagged, spared) = if options.prune.is_active() {
            let crit = &options.prune;
            let mut flags = vec![false; bound.len()];
            let mut or = |mask: Vec<bool>| {
                flags.iter_mut().zip(mask).for_each(|(f, m)| *f |= m);
            };
            if let Some(d) = crit.outlier {
                or(outlier_mask(&new_world, crit.k, d)
                    .map_err(|e| stage("prune")(e.to_string()))?);
            }
            if let Some(c) = crit.normal {
                let mask = match crit.gate {
                    Gate::Seed => normal_deviation_mask(&new_world, crit.k, c),
                    Gate::Stable => normal_inconsistency_mask(&new_world, crit.k, c),
                };
                or(mask.map_err(|e| stage("prune")(e.to_string()))?);
            }
            let mut counts = TriangleCounts::from_set(&bound, triangle_count)
                .map_err(|e| stage("prune")(e.to_string()))?;
            let pruned = prune(&bound, &flags, Some(&mut counts))
                .map_err(|e| stage("prune")(e.to_string()))?;
            let means: Vec<Vec3> = pruned
                .result
                .sources
                .iter()
                .map(|&i| new_world.means()[i])
                .collect();
            let n_flagged = flags.iter().filter(|&&f| f).count();
            (pruned.result.set, means, n_flagged, pruned.spared)
        } else {
            let means = new_world.means().to_vec();
            (bound, means, 0, 0)
        };
        ms.prune = ms_since(t);

        // 8. chamfer
        let t = Instant::now();
        let chamfer_after = centre_chamfer(&next_means, template, &template_samples, &bvh)
            .map_err(stage("chamfer"))?;
        ms.chamfer += ms_since(t);
        chamfer_now = Some(chamfer_after);

        let covered_triangles = TriangleCounts::from_set(&next, triangle_count)
            .map_err(|e| stage("bind")(e.to_string()))?
            .counts()
            .iter()
            .filter(|&&c| c > 0)
            .count();
        let report = RoundReport {
            round,
            before: current.len(),
            after: next.len(),
            alpha,
            alpha_vertices: surface.vertex_count(),
            alpha_triangles: surface.triangle_count(),
            pieces,
            kept_pieces,
            samples: new_count,
            refilled: refill.len(),
            flagged,
            pruned: (new_count + refill.len()).saturating_sub(next.len()),
            spared,
            covered_triangles,
            chamfer_before,
            chamfer_after,
            ms,
            total_ms: ms_since(start),
        };
        on_round(
            &report,
            &RoundSurfaces {
                alpha: &surface,
                smoothed: &smoothed,
            },
        );
        reports.push(report);
        current = next;
    }
    Ok(Refined {
        set: current,
        rounds: reports,
    })
}
