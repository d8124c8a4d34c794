//! Densification and pruning with binding inheritance (docs/conventions.md §4, GaussianAvatars' rules), and the
//! selection criteria that do not need a renderer: the Wasserstein gate, outlier and
//! normal-consistency pruning.
//!
//! Selection masks come from the caller (gradient statistics arrive with the renderer). The
//! operations keep the invariants of a bound set:
//! - a **clone** copies the parameters (local ones for a bound set) and the parent's triangle;
//! - a **split** replaces the parent by `children` Gaussians sampled in the parent's frame
//!   (`mu + R (s ∘ z)`, `z ~ N(0, I)`, log-scales shrunk by `ln(shrink · children)`), each
//!   inheriting the parent's triangle;
//! - a **prune** never empties a triangle: when every Gaussian of a triangle is flagged, none of
//!   them is removed;
//! - [`TriangleCounts`] passed along are updated in place and always equal a recount.
//!
//! Every operation also returns, for each output Gaussian, the input Gaussian it came from, so a
//! caller can carry optimiser state along. Random sampling uses one seeded stream per parent
//! (`Rng::stream(seed, parent)`): results do not depend on the thread count or on the order.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriId;
use trisplat_geometry::rng::Rng;
use trisplat_geometry::spatial::PointIndex;

use crate::gaussians::{GaussianParts, GaussianSet, ScaleDims};
use crate::wasserstein::{covariance_axes, w2_sq};

/// GaussianAvatars/3DGS split shrink: children's scales are the parent's divided by
/// `0.8 × children`.
pub const DEFAULT_SPLIT_SHRINK: f64 = 0.8;

/// Default number of children of a split (3DGS `N = 2`).
pub const DEFAULT_SPLIT_CHILDREN: usize = 2;

/// Default neighbour count of outlier and normal-consistency pruning (docs/conventions.md §4: k = 5).
pub const DEFAULT_NEIGHBOURS: usize = 5;

/// The seed's (GSDHuman's) split threshold ε_w: a Gaussian splits where the squared
/// 2-Wasserstein distance to its children exceeds it (scene units², absolute).
pub const SEED_W2_SQ: f64 = 0.012;

/// The seed's (GSDHuman's) outlier threshold ε_o: pruned where the mean distance to the
/// [`DEFAULT_NEIGHBOURS`] nearest other Gaussians exceeds it (scene units, absolute).
pub const SEED_OUTLIER: f64 = 0.015;

/// The seed's (GSDHuman's) normal-consistency threshold ε_n: pruned where the mean normal
/// deviation `1 - |cos|` to the [`DEFAULT_NEIGHBOURS`] nearest other Gaussians exceeds it.
pub const SEED_NORMAL: f64 = 0.3;

/// The two forms of the densification and pruning criteria (docs/conventions.md §4).
///
/// Both compare the same measured quantities; they differ in form and defaults:
///
/// | criterion | [`Gate::Seed`] (GSDHuman) | [`Gate::Stable`] |
/// |---|---|---|
/// | split | `W² > ε_w` (absolute, default [`SEED_W2_SQ`]) | `√W² > W k_f` (relative to the triangle scale, no default) |
/// | outliers | mean k-NN distance `> ε_o` (default [`SEED_OUTLIER`]) | the same, no default |
/// | normals | mean `1 - abs(cos)` `> ε_n` (default [`SEED_NORMAL`]) | mean `abs(cos)` `< C`, no default |
///
/// With `W = √ε_w / k_f` (every `k_f` equal, or an unbound set with `k_f = 1`) and
/// `C = 1 - ε_n` the two select the same Gaussians.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Gate {
    /// GSDHuman's absolute thresholds and defaults.
    Seed,
    /// The scale-free form: thresholds relative to the triangle scale, none by default.
    #[default]
    Stable,
}

/// Which Gaussians the Wasserstein gate measures a Gaussian against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum W2Pairs {
    /// Its own split children (GSDHuman): the mean of `W²` over the children.
    Children,
    /// Its nearest other Gaussian by position.
    Nearest,
}

/// Errors of densification and pruning.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DensifyError {
    /// A selection mask does not have one entry per Gaussian.
    #[error("the mask has {len} entries for {expected} Gaussians")]
    MaskLength {
        /// Mask length.
        len: usize,
        /// Number of Gaussians.
        expected: usize,
    },
    /// Counts were given for a set without a binding.
    #[error("triangle counts need a bound set")]
    NotBound,
    /// A binding names a triangle past the counts.
    #[error("Gaussian {index}: bound to triangle {triangle}, but there are {triangle_count}")]
    BindingOutOfRange {
        /// Gaussian index.
        index: usize,
        /// Its triangle.
        triangle: TriId,
        /// Number of triangles.
        triangle_count: usize,
    },
    /// A split needs at least one child.
    #[error("a split needs at least one child")]
    NoChildren,
    /// Neighbour queries failed (non-finite or huge means).
    #[error("neighbour search: {0}")]
    Neighbours(String),
    /// A child names a parent past the parents.
    #[error("child {child}: its parent {parent} is past the {parents} parents")]
    ParentOutOfRange {
        /// Child index.
        child: usize,
        /// The parent it names.
        parent: usize,
        /// Number of parents.
        parents: usize,
    },
}

/// Number of Gaussians bound to each triangle.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TriangleCounts {
    counts: Vec<u32>,
}

impl TriangleCounts {
    /// Counts the bindings of `set` over `triangle_count` triangles.
    ///
    /// # Errors
    /// [`DensifyError::NotBound`], [`DensifyError::BindingOutOfRange`].
    pub fn from_set(set: &GaussianSet, triangle_count: usize) -> Result<Self, DensifyError> {
        let binding = set.binding().ok_or(DensifyError::NotBound)?;
        let mut counts = vec![0u32; triangle_count];
        for (index, t) in binding.triangles.iter().enumerate() {
            let Some(c) = counts.get_mut(t.index()) else {
                return Err(DensifyError::BindingOutOfRange {
                    index,
                    triangle: *t,
                    triangle_count,
                });
            };
            *c += 1;
        }
        Ok(Self { counts })
    }

    /// The count of every triangle.
    #[must_use]
    pub fn counts(&self) -> &[u32] {
        &self.counts
    }

    /// The count of triangle `t` (0 past the end).
    #[must_use]
    pub fn get(&self, t: TriId) -> u32 {
        self.counts.get(t.index()).copied().unwrap_or(0)
    }

    fn check<'a>(&self, set: &'a GaussianSet) -> Result<&'a [TriId], DensifyError> {
        let binding = set.binding().ok_or(DensifyError::NotBound)?;
        let n = self.counts.len();
        match binding.triangles.iter().position(|t| t.index() >= n) {
            Some(index) => Err(DensifyError::BindingOutOfRange {
                index,
                triangle: binding.triangles[index],
                triangle_count: n,
            }),
            None => Ok(&binding.triangles),
        }
    }
}

/// The result of an operation: the new set and, for each of its Gaussians, the index of the
/// input Gaussian it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Densified {
    /// The new set.
    pub set: GaussianSet,
    /// `sources[j]` is the input index output Gaussian `j` came from.
    pub sources: Vec<usize>,
}

fn check_mask(set: &GaussianSet, mask: &[bool]) -> Result<(), DensifyError> {
    if mask.len() == set.len() {
        Ok(())
    } else {
        Err(DensifyError::MaskLength {
            len: mask.len(),
            expected: set.len(),
        })
    }
}

/// Clones the selected Gaussians: the output is every input Gaussian in order, then a copy of
/// each selected one (same parameters, same triangle). `counts`, if given, are updated.
///
/// # Errors
/// [`DensifyError::MaskLength`]; with `counts`, [`DensifyError::NotBound`] and
/// [`DensifyError::BindingOutOfRange`].
pub fn clone_selected(
    set: &GaussianSet,
    mask: &[bool],
    counts: Option<&mut TriangleCounts>,
) -> Result<Densified, DensifyError> {
    check_mask(set, mask)?;
    let mut sources: Vec<usize> = (0..set.len()).collect();
    sources.extend((0..set.len()).filter(|&i| mask[i]));
    if let Some(counts) = counts {
        let tris = counts.check(set)?;
        for &i in &sources[set.len()..] {
            counts.counts[tris[i].index()] += 1;
        }
    }
    Ok(Densified {
        set: set.select(&sources),
        sources,
    })
}

/// Options of [`split_selected`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitOptions {
    /// Children per split parent ([`DEFAULT_SPLIT_CHILDREN`]).
    pub children: usize,
    /// Scale shrink factor ([`DEFAULT_SPLIT_SHRINK`]): children's scales are the parent's
    /// divided by `shrink × children`.
    pub shrink: f64,
    /// Seed of the sampling streams.
    pub seed: u64,
}

impl Default for SplitOptions {
    fn default() -> Self {
        Self {
            children: DEFAULT_SPLIT_CHILDREN,
            shrink: DEFAULT_SPLIT_SHRINK,
            seed: 0,
        }
    }
}

/// A standard normal sample (Box–Muller).
fn normal(rng: &mut Rng) -> f64 {
    let u1 = 1.0 - rng.uniform_f64(); // (0, 1]
    let u2 = rng.uniform_f64();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Splits the selected Gaussians: the output is every unselected Gaussian in order, then the
/// `children` children of each selected one (consecutive, in parent order). Children are
/// sampled in the parent's frame (the local frame of a bound set, which is equivalent to
/// GaussianAvatars' world-space sampling mapped back to the triangle), inherit the parent's
/// triangle, opacity, colour and extras, and have log-scales `log_s - ln(shrink · children)`.
/// A surfel's flat axis gets no offset. `counts`, if given, are updated.
///
/// # Errors
/// [`DensifyError::MaskLength`], [`DensifyError::NoChildren`]; with `counts`,
/// [`DensifyError::NotBound`] and [`DensifyError::BindingOutOfRange`].
pub fn split_selected(
    set: &GaussianSet,
    mask: &[bool],
    options: &SplitOptions,
    counts: Option<&mut TriangleCounts>,
) -> Result<Densified, DensifyError> {
    check_mask(set, mask)?;
    if options.children == 0 {
        return Err(DensifyError::NoChildren);
    }
    let parents: Vec<usize> = (0..set.len()).filter(|&i| mask[i]).collect();
    let mut sources: Vec<usize> = (0..set.len()).filter(|&i| !mask[i]).collect();
    let kept = sources.len();
    for &p in &parents {
        sources.extend(std::iter::repeat_n(p, options.children));
    }
    if let Some(counts) = counts {
        let tris = counts.check(set)?;
        for &p in &parents {
            let c = &mut counts.counts[tris[p].index()];
            // `children` new ones, the parent removed.
            *c = (*c as usize + options.children - 1).min(u32::MAX as usize) as u32;
        }
    }
    let mut parts: GaussianParts = set.select(&sources).into_parts();
    let shrink = (options.shrink * options.children as f64).ln() as f32;
    let surfel = set.scale_dims() == ScaleDims::Two;
    // Children of parent k occupy kept + k*children .. kept + (k+1)*children.
    let offsets: Vec<(usize, Vec<Vec3>)> = parents
        .par_iter()
        .enumerate()
        .map(|(k, &p)| {
            let mut rng = Rng::stream(options.seed, p as u64);
            let r = set.rotation_matrix(p);
            let s = set.scale(p).as_dvec3();
            let mean = set.means()[p].as_dvec3();
            let children = (0..options.children)
                .map(|_| {
                    let z = DVec3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
                    let z = if surfel { DVec3::new(z.x, z.y, 0.0) } else { z };
                    (mean + r * (s * z)).as_vec3()
                })
                .collect();
            (kept + k * options.children, children)
        })
        .collect();
    for (start, children) in offsets {
        for (j, m) in children.into_iter().enumerate() {
            parts.means[start + j] = m;
            parts.log_scales[start + j] -= Vec3::splat(shrink);
        }
    }
    Ok(Densified {
        set: GaussianSet::new_unchecked(parts),
        sources,
    })
}

/// The result of [`prune`].
#[derive(Clone, Debug, PartialEq)]
pub struct Pruned {
    /// The remaining Gaussians (in input order) and their input indices.
    pub result: Densified,
    /// Flagged Gaussians kept because removing them would have emptied their triangle.
    pub spared: usize,
}

/// Removes the flagged Gaussians, except that a bound set never loses the last Gaussians of a
/// triangle: if every Gaussian of a triangle is flagged, none of them is removed
/// (GaussianAvatars). `counts`, if given, are updated.
///
/// # Errors
/// [`DensifyError::MaskLength`]; for a bound set [`DensifyError::BindingOutOfRange`] when a
/// binding is past `counts`.
pub fn prune(
    set: &GaussianSet,
    mask: &[bool],
    counts: Option<&mut TriangleCounts>,
) -> Result<Pruned, DensifyError> {
    check_mask(set, mask)?;
    let mut remove = mask.to_vec();
    let mut spared = 0;
    if let Some(binding) = set.binding() {
        let tri_count = match &counts {
            Some(c) => c.counts.len(),
            None => binding
                .triangles
                .iter()
                .map(|t| t.index() + 1)
                .max()
                .unwrap_or(0),
        };
        let mut total = vec![0u32; tri_count];
        let mut flagged = vec![0u32; tri_count];
        for (index, (t, &m)) in binding.triangles.iter().zip(mask).enumerate() {
            let Some(c) = total.get_mut(t.index()) else {
                return Err(DensifyError::BindingOutOfRange {
                    index,
                    triangle: *t,
                    triangle_count: tri_count,
                });
            };
            *c += 1;
            flagged[t.index()] += u32::from(m);
        }
        for (r, t) in remove.iter_mut().zip(&binding.triangles) {
            if *r && flagged[t.index()] == total[t.index()] {
                *r = false;
                spared += 1;
            }
        }
        if let Some(counts) = counts {
            for (t, &r) in binding.triangles.iter().zip(&remove) {
                let c = &mut counts.counts[t.index()];
                *c = c.saturating_sub(u32::from(r));
            }
        }
    } else if counts.is_some() {
        return Err(DensifyError::NotBound);
    }
    let sources: Vec<usize> = (0..set.len()).filter(|&i| !remove[i]).collect();
    Ok(Pruned {
        result: Densified {
            set: set.select(&sources),
            sources,
        },
        spared,
    })
}

fn index_of(set: &GaussianSet) -> Result<Option<PointIndex>, DensifyError> {
    if set.is_empty() {
        return Ok(None);
    }
    PointIndex::new(set.means())
        .map(Some)
        .map_err(|e| DensifyError::Neighbours(e.to_string()))
}

/// For each Gaussian, the squared Wasserstein-2 distance `W²` to its nearest neighbour by
/// position (`f64::INFINITY` when alone; never negative). Pass a world-space set (e.g. the
/// template at rest).
///
/// # Errors
/// [`DensifyError::Neighbours`] when the means are not finite.
pub fn w2_sq_to_nearest(set: &GaussianSet) -> Result<Vec<f64>, DensifyError> {
    let Some(index) = index_of(set)? else {
        return Ok(Vec::new());
    };
    Ok((0..set.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            let found = index.k_nearest(set.means()[i], 2);
            let Some(j) = found.iter().map(|n| n.index as usize).find(|&j| j != i) else {
                return f64::INFINITY;
            };
            w2_sq(
                set.means()[i].as_dvec3(),
                covariance_axes(set, i),
                set.means()[j].as_dvec3(),
                covariance_axes(set, j),
            )
            .max(0.0)
        })
        .collect())
}

/// For each Gaussian, the Wasserstein-2 distance (not squared) to its nearest neighbour by
/// position (`f64::INFINITY` when alone): the square root of [`w2_sq_to_nearest`].
///
/// # Errors
/// [`DensifyError::Neighbours`] when the means are not finite.
pub fn w2_to_nearest(set: &GaussianSet) -> Result<Vec<f64>, DensifyError> {
    Ok(w2_sq_to_nearest(set)?.into_iter().map(f64::sqrt).collect())
}

/// For each parent, the mean over its children of the squared Wasserstein-2 distance
/// `W²(parent, child)` (GSDHuman's split criterion): `children[j]` is a child of
/// `parents[sources[j]]`, both sets in the same frame (world space: a bound split baked at
/// the template's rest). A parent without children gets 0 (it never passes the gate).
///
/// For a split of [`split_selected`] (children at `mu + R (s ∘ z)`, scales `c s` with
/// `c = 1 / (shrink · children)`, same rotation) the expectation is
/// `E W² = Σ s_i² + (1 - c)² Σ s_i²` (a surfel's flat axis has no offset).
///
/// # Errors
/// [`DensifyError::MaskLength`] when `sources` does not have one entry per child,
/// [`DensifyError::ParentOutOfRange`] when one names no parent.
pub fn w2_sq_to_children(
    parents: &GaussianSet,
    children: &GaussianSet,
    sources: &[usize],
) -> Result<Vec<f64>, DensifyError> {
    if sources.len() != children.len() {
        return Err(DensifyError::MaskLength {
            len: sources.len(),
            expected: children.len(),
        });
    }
    if let Some((child, &parent)) = sources
        .iter()
        .enumerate()
        .find(|(_, p)| **p >= parents.len())
    {
        return Err(DensifyError::ParentOutOfRange {
            child,
            parent,
            parents: parents.len(),
        });
    }
    let per_child: Vec<f64> = (0..children.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|j| {
            let p = sources[j];
            w2_sq(
                parents.means()[p].as_dvec3(),
                covariance_axes(parents, p),
                children.means()[j].as_dvec3(),
                covariance_axes(children, j),
            )
            .max(0.0)
        })
        .collect();
    let mut sum = vec![0.0f64; parents.len()];
    let mut count = vec![0u32; parents.len()];
    for (&p, d) in sources.iter().zip(per_child) {
        sum[p] += d;
        count[p] += 1;
    }
    Ok(sum
        .into_iter()
        .zip(count)
        .map(|(s, c)| if c == 0 { 0.0 } else { s / f64::from(c) })
        .collect())
}

/// The seed's (GSDHuman's) Wasserstein gate: Gaussian `i` may split only if `w2_sq[i]`
/// (squared, absolute, e.g. from [`w2_sq_to_children`]) exceeds `eps_w` ([`SEED_W2_SQ`]).
#[must_use]
pub fn seed_w2_gate(w2_sq: &[f64], eps_w: f64) -> Vec<bool> {
    w2_sq.iter().map(|&d| d > eps_w).collect()
}

/// The stable Wasserstein gate: Gaussian `i` may densify only if `w2[i]` (the distance, not
/// squared) exceeds `threshold × scale[i]` (thresholds relative to the triangle scale `k_f`,
/// docs/conventions.md §4; [`seed_w2_gate`] is the seed's absolute squared form). Returns
/// the mask of Gaussians allowed to densify; combine it with the caller's selection.
///
/// # Errors
/// [`DensifyError::MaskLength`] when the slices differ in length.
pub fn w2_gate(w2: &[f64], scale: &[f64], threshold: f64) -> Result<Vec<bool>, DensifyError> {
    if w2.len() != scale.len() {
        return Err(DensifyError::MaskLength {
            len: scale.len(),
            expected: w2.len(),
        });
    }
    Ok(w2
        .iter()
        .zip(scale)
        .map(|(&d, &k)| d > threshold * k)
        .collect())
}

/// Outlier mask: the mean distance to the `k` nearest other Gaussians is above `threshold`.
/// Pass a world-space set.
///
/// # Errors
/// [`DensifyError::Neighbours`] when the means are not finite.
pub fn outlier_mask(
    set: &GaussianSet,
    k: usize,
    threshold: f64,
) -> Result<Vec<bool>, DensifyError> {
    let Some(index) = index_of(set)? else {
        return Ok(Vec::new());
    };
    Ok(
        mean_over_neighbours(set, &index, k, |_, _, distance| distance)
            .into_iter()
            .map(|mean| mean.is_some_and(|m| m > threshold))
            .collect(),
    )
}

/// A Gaussian's normal: its shortest axis (the flat axis of a surfel), in the set's frame.
///
/// # Panics
/// If `i >= set.len()`.
#[must_use]
pub fn shortest_axis(set: &GaussianSet, i: usize) -> DVec3 {
    let r = set.rotation_matrix(i);
    let s = set.scale(i);
    if s.x <= s.y && s.x <= s.z {
        r.x_axis
    } else if s.y <= s.z {
        r.y_axis
    } else {
        r.z_axis
    }
}

/// Normal-consistency mask: the mean `|cos|` between a Gaussian's normal (shortest axis) and
/// those of its `k` nearest other Gaussians is below `threshold`. Pass a world-space set.
///
/// # Errors
/// [`DensifyError::Neighbours`] when the means are not finite.
pub fn normal_inconsistency_mask(
    set: &GaussianSet,
    k: usize,
    threshold: f64,
) -> Result<Vec<bool>, DensifyError> {
    normal_mean_mask(set, k, |abs_cos| abs_cos, |mean| mean < threshold)
}

/// The seed's (GSDHuman's) normal-consistency mask: the mean normal deviation `1 - |cos|`
/// between a Gaussian's normal (shortest axis) and those of its `k` nearest other Gaussians
/// is above `eps_n` ([`SEED_NORMAL`]). Equals [`normal_inconsistency_mask`] with threshold
/// `1 - eps_n` (up to rounding at the threshold). Pass a world-space set.
///
/// # Errors
/// [`DensifyError::Neighbours`] when the means are not finite.
pub fn normal_deviation_mask(
    set: &GaussianSet,
    k: usize,
    eps_n: f64,
) -> Result<Vec<bool>, DensifyError> {
    normal_mean_mask(set, k, |abs_cos| 1.0 - abs_cos, |mean| mean > eps_n)
}

/// For every Gaussian, whether `keep` holds for the mean of `pair(|cos|)` between its normal
/// (shortest axis) and those of its `k` nearest other Gaussians (false when it has none).
fn normal_mean_mask(
    set: &GaussianSet,
    k: usize,
    pair: impl Fn(f64) -> f64 + Sync,
    keep: impl Fn(f64) -> bool,
) -> Result<Vec<bool>, DensifyError> {
    let Some(index) = index_of(set)? else {
        return Ok(Vec::new());
    };
    let normals: Vec<DVec3> = (0..set.len())
        .into_par_iter()
        .map(|i| shortest_axis(set, i))
        .collect();
    Ok(mean_over_neighbours(set, &index, k, |i, j, _| {
        pair(normals[i].dot(normals[j]).abs())
    })
    .into_iter()
    .map(|mean| mean.is_some_and(&keep))
    .collect())
}

/// For every Gaussian, the mean of `value(i, j, distance)` over its `k` nearest other
/// Gaussians `j` (`None` when it has none).
fn mean_over_neighbours(
    set: &GaussianSet,
    index: &PointIndex,
    k: usize,
    value: impl Fn(usize, usize, f64) -> f64 + Sync,
) -> Vec<Option<f64>> {
    (0..set.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            let (sum, count) = index
                .k_nearest(set.means()[i], k + 1)
                .iter()
                .filter(|n| n.index as usize != i)
                .take(k)
                .fold((0.0, 0usize), |(sum, count), n| {
                    (sum + value(i, n.index as usize, n.distance), count + 1)
                });
            (count > 0).then(|| sum / count as f64)
        })
        .collect()
}
