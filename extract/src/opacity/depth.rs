//! The median-depth field (docs/conventions.md §6, `--field median`): the sign of a point comes
//! from the views' rendered median-depth maps, the renderer's own rule for where a surface is,
//! instead of from walks along rays. A view *carves* a point it sees when the pixel the point
//! falls in is not covered (alpha ≤ 1/2: no median depth) or when the point lies in front of
//! that pixel's median depth by more than a margin; the field is the `k`-th smallest over the
//! views that see the point of the signed depth `(z - D) f / z` (in pixel footprints at the
//! point's depth), so a point is outside when at least `k` views carve it.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::error::OpacityError;
use super::order::z_order;
use super::view::NEAR;

/// Largest number of views that must carve a point ([`DepthRules::carve_views`]).
pub const MAX_CARVE_VIEWS: u16 = 16;

/// Largest spread of a pixel quad's four median depths, in pixel footprints, over which the
/// depth is interpolated bilinearly; beyond it (an occlusion edge) the point's own pixel's
/// depth is used, so depths of two surfaces are never blended.
pub const BLEND_SPREAD: f64 = 8.0;

/// One view's rendered median-depth map (docs/conventions.md §5: the z-depth of the splat at
/// which the transmittance first drops below 1/2), as plain arrays.
#[derive(Clone, Debug)]
pub struct DepthView {
    /// The camera.
    pub camera: Camera,
    /// Row-major `height x width`: the median depth where the Gaussians cover the pixel
    /// (alpha > 1/2, depth finite and positive), 0 elsewhere.
    pub depth: Vec<f32>,
    /// Row-major rendered colours (linear RGB), for vertex colours; empty: none.
    pub rgb: Vec<[f32; 3]>,
}

/// How the median-depth maps decide a point's side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthRules {
    /// A view carves a point in front of its median depth by more than this many pixel
    /// footprints at the point's depth (`z / f`): the surface lies this far in front of the
    /// carving view's median depth, and layers one Gaussian thick keep an inside.
    pub margin: f32,
    /// A point is outside when at least this many views carve it (1: any view, the strict
    /// depth-carved hull; more keeps semi-transparent rims that one view sees through).
    pub carve_views: u16,
    /// Every `sample_stride`-th pixel (in rows and columns) of every covered map adds two
    /// points to the tetrahedralisation, half a footprint behind its median depth and
    /// `margin + 1/2` footprints in front of it, so the marching sees the surface where the
    /// Gaussians' own points are too sparse (thin or fuzzy layers); 0: GOF's points only.
    pub sample_stride: u32,
    /// Where the vertices settle, in pixel footprints in front of the median depth (0..=
    /// `margin`): the margin decides which points are inside (so that a layer one Gaussian
    /// thick keeps an inside) and puts the level set `margin` footprints in front of the
    /// median depth; each vertex is then moved along the surface's inward normal, by at most
    /// `margin - surface` footprints, to the first point where the field reaches `-surface`,
    /// when the field stays at or above it for another `margin - surface` footprints behind
    /// (a thick part). Vertices of thin layers (which the margin keeps) and on the silhouette
    /// (carved by an uncovered pixel just outside them) stay. `margin`: no move (the level set
    /// of the inside test, the behaviour before this rule).
    pub surface: f32,
}

/// Default [`DepthRules::margin`], pixel footprints (with [`DEFAULT_CARVE_VIEWS`] the setting
/// that beats GOF's field on every render-consistency score on LAM, docs/benchmarks.md).
pub const DEFAULT_MARGIN: f32 = 3.0;
/// Default [`DepthRules::sample_stride`].
pub const DEFAULT_SAMPLE_STRIDE: u32 = 0;
/// Default [`DepthRules::carve_views`].
pub const DEFAULT_CARVE_VIEWS: u16 = 2;
/// Default [`DepthRules::surface`]: on the median depth itself, the depth render consistency
/// measures.
pub const DEFAULT_SURFACE: f32 = 0.0;

impl Default for DepthRules {
    fn default() -> Self {
        Self {
            margin: DEFAULT_MARGIN,
            carve_views: DEFAULT_CARVE_VIEWS,
            sample_stride: DEFAULT_SAMPLE_STRIDE,
            surface: DEFAULT_SURFACE,
        }
    }
}

/// A [`DepthView`] with its projection at hand.
struct Prepared<'a> {
    view: &'a DepthView,
    /// World to camera.
    rot: DMat3,
    origin: DVec3,
    /// Mean focal length (pixels): a pixel's footprint at depth `z` is `z / focal`.
    focal: f64,
}

/// The checked views of the field's queries ([`DepthViews::at_or_above`]) and [`depth_colors`].
pub(crate) struct DepthViews<'a> {
    views: Vec<Prepared<'a>>,
    rules: DepthRules,
}

impl<'a> DepthViews<'a> {
    /// Checks the maps' sizes and the rules.
    ///
    /// # Errors
    /// [`OpacityError::NoCameras`] without views, [`OpacityError::BadDepthMap`] for a map or
    /// colour image of the wrong size or a depth that is negative or not finite,
    /// [`OpacityError::BadDepthRules`] for a margin that is negative or not finite or a
    /// `carve_views` outside 1..=[`MAX_CARVE_VIEWS`].
    pub fn new(views: &'a [DepthView], rules: DepthRules) -> Result<Self, OpacityError> {
        if views.is_empty() {
            return Err(OpacityError::NoCameras);
        }
        let margin_ok = rules.margin.is_finite()
            && rules.margin >= 0.0
            && rules.surface.is_finite()
            && (0.0..=rules.margin).contains(&rules.surface);
        if !margin_ok || !(1..=MAX_CARVE_VIEWS).contains(&rules.carve_views) {
            return Err(OpacityError::BadDepthRules {
                margin: rules.margin,
                surface: rules.surface,
                carve_views: rules.carve_views,
            });
        }
        let mut out = Vec::with_capacity(views.len());
        for (index, view) in views.iter().enumerate() {
            let c = &view.camera;
            let pixels = c.width as usize * c.height as usize;
            let bad = |problem: String| OpacityError::BadDepthMap {
                view: index,
                name: c.name.clone(),
                problem,
            };
            if view.depth.len() != pixels {
                return Err(bad(format!(
                    "{} depths for {}x{} pixels",
                    view.depth.len(),
                    c.width,
                    c.height
                )));
            }
            if !view.rgb.is_empty() && view.rgb.len() != pixels {
                return Err(bad(format!(
                    "{} colours for {}x{} pixels",
                    view.rgb.len(),
                    c.width,
                    c.height
                )));
            }
            if let Some(k) = view
                .depth
                .iter()
                .position(|d| !(d.is_finite() && *d >= 0.0))
            {
                return Err(bad(format!(
                    "pixel {k} has depth {} (expected finite and >= 0)",
                    view.depth[k]
                )));
            }
            out.push(Prepared {
                view,
                rot: c.world_to_camera_rotation(),
                origin: c.position(),
                focal: 0.5 * (c.fx + c.fy),
            });
        }
        Ok(Self { views: out, rules })
    }

    /// The level: a point is inside when its field is at least this.
    pub fn level(&self) -> f64 {
        -f64::from(self.rules.margin)
    }

    /// The settling of [`DepthRules::surface`]: `vertices` (on the level set) moved along
    /// `-normals` (unit, outward) as that rule says; with `hold_rims` false, vertices just
    /// outside which views see no median depth settle too (a solid body's level set lies on
    /// its visual hull there, which grazing views carve; `OpacityOptions::settle_rims`). The
    /// vertices are visited in Z-order, each one's queries starting from the views that carved
    /// its predecessor's last sample.
    pub fn settle_with(
        &self,
        vertices: &[DVec3],
        normals: &[DVec3],
        hold_rims: bool,
    ) -> Vec<DVec3> {
        let target = -f64::from(self.rules.surface);
        let reach = f64::from(self.rules.margin - self.rules.surface);
        if reach <= 0.0 {
            return vertices.to_vec();
        }
        let order = z_order(vertices);
        let by_order: Vec<DVec3> = order
            .par_chunks(SIDE_CHUNK)
            .flat_map_iter(|chunk| {
                let mut hint = CarveHint::default();
                chunk.iter().map(move |&i| {
                    let i = i as usize;
                    self.settle_one(vertices[i], normals[i], target, reach, hold_rims, &mut hint)
                })
            })
            .collect();
        let mut out = vec![DVec3::ZERO; vertices.len()];
        for (&i, &x) in order.iter().zip(&by_order) {
            out[i as usize] = x;
        }
        out
    }

    /// One vertex of [`Self::settle_with`]; `hint` carries the views that carved the last sample
    /// below the target from query to query.
    fn settle_one(
        &self,
        x: DVec3,
        n: DVec3,
        target: f64,
        reach: f64,
        hold_rims: bool,
        hint: &mut CarveHint,
    ) -> DVec3 {
        if n == DVec3::ZERO {
            return x;
        }
        let Some(fp) = self.footprint(x) else {
            return x;
        };
        // Silhouette: just outside the vertex some view sees no median depth (the field is
        // -inf there, below every finite level).
        let mut rim_hint = CarveHint::default();
        if hold_rims
            && !self
                .at_or_above(x + n * (0.5 * fp), f64::MIN, &mut rim_hint)
                .0
        {
            return x;
        }
        let step = reach * fp / f64::from(SETTLE_SAMPLES);
        let mut at = |t: f64| self.at_or_above(x - n * t, target, hint).0;
        if at(0.0) {
            return x;
        }
        for i in 1..=SETTLE_SAMPLES {
            let t = step * f64::from(i);
            if at(t) {
                let (mut lo, mut hi) = (t - step, t);
                for _ in 0..SETTLE_BISECTIONS {
                    let mid = 0.5 * (lo + hi);
                    if at(mid) {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                let t = 0.5 * (lo + hi);
                // Only where the inside goes on behind the target (a thick part): a thin layer
                // keeps the margin that gives it an inside, so it is not thinned away.
                let thick = (1..=2).all(|k| at(t + f64::from(k) * 0.5 * reach * fp));
                return if thick { x - n * t } else { x };
            }
        }
        x
    }

    /// A pixel footprint at `x` (`z / f`), averaged over the views that see it.
    fn footprint(&self, x: DVec3) -> Option<f64> {
        let (mut sum, mut count) = (0.0, 0u32);
        for v in &self.views {
            if let Some((z, _, _)) = locate(v, x) {
                sum += z / v.focal;
                count += 1;
            }
        }
        (count > 0).then(|| sum / f64::from(count))
    }
}

/// Samples along the inward normal of [`DepthViews::settle`].
pub const SETTLE_SAMPLES: u32 = 8;
/// Bisection steps of [`DepthViews::settle`] between the last sample below the target and the
/// first at or above it.
pub const SETTLE_BISECTIONS: u32 = 4;

/// Where `x` falls in `v`: camera z and pixel coordinates (u, v), `None` behind the near plane
/// or outside the image.
#[inline]
fn locate(v: &Prepared, x: DVec3) -> Option<(f64, f64, f64)> {
    let c = v.rot * (x - v.origin);
    if c.z.is_nan() || c.z <= NEAR {
        return None;
    }
    let cam = &v.view.camera;
    let u = cam.fx * c.x / c.z + cam.cx;
    let w = cam.fy * c.y / c.z + cam.cy;
    if !(u >= 0.0 && w >= 0.0 && u < f64::from(cam.width) && w < f64::from(cam.height)) {
        return None;
    }
    Some((c.z, u, w))
}

impl DepthView {
    /// The median depth this view shows at pixel coordinates (u, w), inside the image: bilinear over the four pixel
    /// centres around it when all four are covered and their depths spread by at most
    /// [`BLEND_SPREAD`] footprints, else the depth of the pixel it falls in; 0 when that pixel is
    /// not covered.
    #[inline]
    #[must_use]
    pub fn median_at(&self, focal: f64, u: f64, w: f64) -> f64 {
        let (width, height) = (self.camera.width as usize, self.camera.height as usize);
        let own = f64::from(self.depth[(w as usize) * width + u as usize]);
        if own <= 0.0 {
            return 0.0;
        }
        let (fu, fw) = (u - 0.5, w - 0.5);
        if fu < 0.0 || fw < 0.0 {
            return own;
        }
        let (i, j) = (fu as usize, fw as usize);
        if i + 1 >= width || j + 1 >= height {
            return own;
        }
        let d = [
            f64::from(self.depth[j * width + i]),
            f64::from(self.depth[j * width + i + 1]),
            f64::from(self.depth[(j + 1) * width + i]),
            f64::from(self.depth[(j + 1) * width + i + 1]),
        ];
        let (lo, hi) = d.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
        if lo <= 0.0 || (hi - lo) * focal > BLEND_SPREAD * own {
            return own;
        }
        let (a, b) = (fu - i as f64, fw - j as f64);
        (d[0] * (1.0 - a) + d[1] * a) * (1.0 - b) + (d[2] * (1.0 - a) + d[3] * a) * b
    }
}

/// The signed depth of `x` in `v`, in pixel footprints (`(z - D) f / z`; −∞ where the pixel is
/// not covered), `None` when `v` does not see `x`.
#[inline]
fn signed(v: &Prepared, x: DVec3) -> Option<f64> {
    let (z, u, w) = locate(v, x)?;
    let d = v.view.median_at(v.focal, u, w);
    Some(if d > 0.0 {
        (z - d) * v.focal / z
    } else {
        f64::NEG_INFINITY
    })
}

/// The field at `x`: the `carve_views`-th smallest signed depth over the views that see `x`
/// (+∞ when fewer see it), and whether any view sees it: the plain rule, which
/// [`DepthViews::at_or_above`] answers without all the views.
#[cfg(test)]
pub(crate) fn field_at(views: &DepthViews, x: DVec3) -> (f64, bool) {
    let k = usize::from(views.rules.carve_views);
    let mut smallest = [f64::INFINITY; MAX_CARVE_VIEWS as usize];
    let mut seen = false;
    for v in &views.views {
        let Some(s) = signed(v, x) else { continue };
        seen = true;
        if s < smallest[k - 1] {
            // Insert into the sorted k smallest.
            let mut at = k - 1;
            while at > 0 && smallest[at - 1] > s {
                smallest[at] = smallest[at - 1];
                at -= 1;
            }
            smallest[at] = s;
        }
    }
    (smallest[k - 1], seen)
}

/// [`field_at`] at every point (values, seen).
#[cfg(test)]
pub(crate) fn depth_field(views: &DepthViews, points: &[DVec3]) -> (Vec<f64>, Vec<bool>) {
    points
        .par_iter()
        .with_min_len(1024)
        .map(|&x| field_at(views, x))
        .unzip()
}

/// The views a [`DepthViews::at_or_above`] query tries first: those that carved the last point
/// it answered outside (consecutive queries lie close together, and a view that carved one
/// point mostly carves its neighbour). Only the order in which the views are asked changes;
/// every answer is the plain rule's. Views past `u16::MAX` are asked but never hinted.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CarveHint {
    views: [u16; MAX_CARVE_VIEWS as usize],
    len: u8,
}

impl CarveHint {
    fn as_slice(&self) -> &[u16] {
        &self.views[..usize::from(self.len)]
    }

    fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// Queries of [`DepthViews::sides`] answered in a row by one task (so that each query's hint
/// can start from its predecessor's); fixed, and no answer depends on it.
const SIDE_CHUNK: usize = 256;

impl DepthViews<'_> {
    /// Whether [`field_at`]`(x)` is at least `t` (`t` finite or `f64::MIN`), and whether any
    /// view sees `x`. The field is the `k`-th smallest signed depth, so it is at least `t`
    /// exactly when fewer than `k` of the views that see `x` have a signed depth below `t`:
    /// the views in `hint` are asked first and the query stops at the `k`-th such view
    /// (`hint` then holds them). With `t = f64::MIN` it asks whether the field is above `-inf`
    /// (only an uncovered pixel's signed depth lies below every finite value).
    #[inline]
    pub(crate) fn at_or_above(&self, x: DVec3, t: f64, hint: &mut CarveHint) -> (bool, bool) {
        let k = usize::from(self.rules.carve_views);
        let mut found = CarveHint::default();
        let mut count = 0usize;
        let mut seen = false;
        let mut ask = |i: usize, found: &mut CarveHint| -> bool {
            if let Some(s) = signed(&self.views[i], x) {
                seen = true;
                if s < t {
                    if let Ok(id) = u16::try_from(i) {
                        found.views[usize::from(found.len)] = id;
                        found.len += 1;
                    }
                    count += 1;
                    return count >= k;
                }
            }
            false
        };
        let first = *hint;
        let hinted = first.as_slice();
        for &i in hinted {
            if ask(usize::from(i), &mut found) {
                *hint = found;
                return (false, true);
            }
        }
        for i in 0..self.views.len() {
            let fresh = !u16::try_from(i).is_ok_and(|id| hinted.contains(&id));
            if fresh && ask(i, &mut found) {
                *hint = found;
                return (false, true);
            }
        }
        (true, seen)
    }

    /// [`Self::at_or_above`] at every point (at or above `t`; seen), evaluated in `order` (a
    /// Z-order of `points`, so that neighbours share pixels and hints), with one hint per
    /// position in `order` in `hints`, carried from call to call (an empty hint starts from
    /// the previous query's).
    pub(crate) fn sides(
        &self,
        points: &[DVec3],
        t: f64,
        order: &[u32],
        hints: &mut [CarveHint],
    ) -> (Vec<bool>, Vec<bool>) {
        let by_order: Vec<(bool, bool)> = order
            .par_chunks(SIDE_CHUNK)
            .zip(hints.par_chunks_mut(SIDE_CHUNK))
            .flat_map_iter(|(chunk, hints)| {
                let mut last = CarveHint::default();
                chunk.iter().zip(hints).map(move |(&i, hint)| {
                    if hint.is_empty() {
                        *hint = last;
                    }
                    let out = self.at_or_above(points[i as usize], t, hint);
                    last = *hint;
                    out
                })
            })
            .collect();
        let mut inside = vec![false; points.len()];
        let mut seen = vec![false; points.len()];
        for (&i, &(a, b)) in order.iter().zip(&by_order) {
            inside[i as usize] = a;
            seen[i as usize] = b;
        }
        (inside, seen)
    }
}

/// The sample points of [`DepthRules::sample_stride`]: per view, per sampled covered pixel
/// (its centre), the points `0.5` footprints behind and `margin + 0.5` in front of its
/// median depth along the pixel's ray; none with a stride of 0.
pub(crate) fn depth_samples(views: &DepthViews) -> Vec<DVec3> {
    let stride = views.rules.sample_stride as usize;
    if stride == 0 {
        return Vec::new();
    }
    let margin = f64::from(views.rules.margin);
    let mut out = Vec::new();
    for v in &views.views {
        let cam = &v.view.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let to_world = v.rot.transpose();
        for row in (stride / 2..h).step_by(stride) {
            for col in (stride / 2..w).step_by(stride) {
                let d = f64::from(v.view.depth[row * w + col]);
                if d <= 0.0 {
                    continue;
                }
                let ray = cam.unproject(col as f64 + 0.5, row as f64 + 0.5);
                for z in [
                    d * (1.0 + 0.5 / v.focal),
                    d * (1.0 - (margin + 0.5) / v.focal),
                ] {
                    if z > NEAR {
                        out.push(to_world * (ray * z) + v.origin);
                    }
                }
            }
        }
    }
    out
}

/// Vertex colours: the rendered colour of the pixel a vertex falls in, in the view whose median
/// depth there is closest to it (in footprints) among the views that see it covered; grey where
/// none does or the views have no colours.
pub(crate) fn depth_colors(views: &DepthViews, points: &[DVec3]) -> Vec<[f32; 3]> {
    points
        .par_iter()
        .with_min_len(1024)
        .map(|&x| {
            let mut best = (f64::INFINITY, [0.5f32; 3]);
            for v in &views.views {
                if v.view.rgb.is_empty() {
                    continue;
                }
                let Some((z, u, w)) = locate(v, x) else {
                    continue;
                };
                let k = (w as usize) * v.view.camera.width as usize + u as usize;
                let d = f64::from(v.view.depth[k]);
                if d <= 0.0 {
                    continue;
                }
                let off = ((z - d) * v.focal / z).abs();
                if off < best.0 {
                    best = (off, v.view.rgb[k]);
                }
            }
            best.1
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};
    use trisplat_geometry::{TriMesh, sphere_rig};

    use super::*;
    use crate::opacity::{OpacityGaussians, OpacityOptions, median_depth_mesh};

    /// The definition, evaluated directly: every view's signed depth through the camera's own
    /// projection, all of them sorted, the `k`-th taken.
    fn brute_force(views: &[DepthView], rules: DepthRules, x: DVec3) -> (f64, bool) {
        let mut all = Vec::new();
        for v in views {
            let cam = &v.camera;
            let c = cam.world_to_camera(x);
            if c.z.is_nan() || c.z <= NEAR {
                continue;
            }
            let uv = cam.project(c);
            let (w, h) = (f64::from(cam.width), f64::from(cam.height));
            if !(uv.x >= 0.0 && uv.y >= 0.0 && uv.x < w && uv.y < h) {
                continue;
            }
            let f = (cam.fx + cam.fy) / 2.0;
            let at = |col: f64, row: f64| {
                f64::from(v.depth[row as usize * cam.width as usize + col as usize])
            };
            let own = at(uv.x.floor(), uv.y.floor());
            let (i, j) = ((uv.x - 0.5).floor(), (uv.y - 0.5).floor());
            let inside = i >= 0.0 && j >= 0.0 && i + 1.0 < w && j + 1.0 < h;
            let quad = if inside {
                [
                    at(i, j),
                    at(i + 1.0, j),
                    at(i, j + 1.0),
                    at(i + 1.0, j + 1.0),
                ]
            } else {
                [0.0; 4]
            };
            let d = if own <= 0.0 {
                0.0
            } else if inside
                && quad.iter().all(|&d| d > 0.0)
                && (quad.iter().copied().fold(0.0, f64::max)
                    - quad.iter().copied().fold(f64::INFINITY, f64::min))
                    * f
                    <= BLEND_SPREAD * own
            {
                let (a, b) = (uv.x - 0.5 - i, uv.y - 0.5 - j);
                quad[0] * (1.0 - a) * (1.0 - b)
                    + quad[1] * a * (1.0 - b)
                    + quad[2] * (1.0 - a) * b
                    + quad[3] * a * b
            } else {
                own
            };
            all.push(if d > 0.0 {
                (c.z - d) * f / c.z
            } else {
                f64::NEG_INFINITY
            });
        }
        all.sort_by(f64::total_cmp);
        let k = usize::from(rules.carve_views);
        (
            all.get(k - 1).copied().unwrap_or(f64::INFINITY),
            !all.is_empty(),
        )
    }

    /// A small deterministic generator (no dependency).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Maps with smooth parts, jumps (occlusion edges) and holes (uncovered pixels), on a
    /// non-square image.
    fn random_views(seed: u64) -> Vec<DepthView> {
        let mut state = seed;
        let cams = sphere_rig(DVec3::ZERO, 1.0, 7, (24, 17), 40.0).expect("rig");
        cams.into_iter()
            .map(|camera| {
                let base = camera.position().length();
                let (w, h) = (camera.width as usize, camera.height as usize);
                let mut depth = vec![0.0f32; w * h];
                for (k, d) in depth.iter_mut().enumerate() {
                    let (col, row) = ((k % w) as f64, (k / w) as f64);
                    let r = lcg(&mut state);
                    *d = if r < 0.15 {
                        0.0
                    } else if col > 14.0 {
                        (base - 0.6 + 0.01 * row) as f32
                    } else {
                        (base + 0.02 * (col * 0.7 + row * 0.3).sin() + 0.002 * r) as f32
                    };
                }
                DepthView {
                    camera,
                    depth,
                    rgb: Vec::new(),
                }
            })
            .collect()
    }

    /// The rules of the field tests: margin and surface 1/2, `k` carving views, no samples.
    fn carving(k: u16) -> DepthRules {
        DepthRules {
            margin: 0.5,
            carve_views: k,
            sample_stride: 0,
            surface: 0.5,
        }
    }

    /// `n` points drawn uniformly in the cube [-1.2, 1.2]^3.
    fn random_points(state: &mut u64, n: usize) -> Vec<DVec3> {
        (0..n)
            .map(|_| DVec3::new(lcg(state), lcg(state), lcg(state)) * 2.4 - DVec3::splat(1.2))
            .collect()
    }

    #[test]
    fn field_equals_brute_force() {
        let views = random_views(7);
        let mut state = 99u64;
        let points = random_points(&mut state, 4000);
        let mut kinds = [0usize; 3];
        for k in [1u16, 2, 3] {
            let rules = carving(k);
            let prepared = DepthViews::new(&views, rules).expect("views");
            let (value, seen) = depth_field(&prepared, &points);
            for (i, &x) in points.iter().enumerate() {
                let (want, want_seen) = brute_force(&views, rules, x);
                assert_eq!(seen[i], want_seen, "point {i}");
                let got = value[i];
                if want.is_finite() {
                    assert!(
                        (got - want).abs() <= 1e-9 * (1.0 + want.abs()),
                        "point {i}, k {k}: {got} against {want}"
                    );
                    kinds[0] += 1;
                } else {
                    assert_eq!(got, want, "point {i}, k {k}");
                    kinds[usize::from(want > 0.0) + 1] += 1;
                }
            }
        }
        // Finite values, carved by uncovered pixels (-inf) and seen by fewer than k views.
        assert!(
            kinds[0] > 1000 && kinds[1] > 1000 && kinds[2] > 0,
            "{kinds:?}"
        );
    }

    #[test]
    fn bad_maps_and_rules_are_refused() {
        let mut views = random_views(1);
        let bad_rules = [
            DepthRules {
                margin: -1.0,
                ..DepthRules::default()
            },
            DepthRules {
                carve_views: 0,
                ..DepthRules::default()
            },
            DepthRules {
                margin: 1.0,
                surface: 2.0,
                ..DepthRules::default()
            },
        ];
        for rules in bad_rules {
            assert!(
                matches!(
                    DepthViews::new(&views, rules),
                    Err(OpacityError::BadDepthRules { .. })
                ),
                "{rules:?}"
            );
        }
        views[2].depth[5] = f32::NAN;
        let err = DepthViews::new(&views, DepthRules::default())
            .err()
            .expect("refused");
        assert!(
            matches!(err, OpacityError::BadDepthMap { view: 2, .. }),
            "{err}"
        );
        views[2].depth.pop();
        assert!(matches!(
            DepthViews::new(&views, DepthRules::default()),
            Err(OpacityError::BadDepthMap { view: 2, .. })
        ));
        assert!(matches!(
            DepthViews::new(&[], DepthRules::default()),
            Err(OpacityError::NoCameras)
        ));
    }

    /// Exact median-depth maps of a sphere of `radius` at the origin (ray cast) from `cams`.
    fn sphere_views(cams: Vec<trisplat_geometry::Camera>, radius: f64) -> Vec<DepthView> {
        cams.into_iter()
            .map(|camera| {
                let (w, h) = (camera.width, camera.height);
                let mut depth = vec![0.0f32; (w * h) as usize];
                for row in 0..h {
                    for col in 0..w {
                        let (o, d) = camera.pixel_ray(row, col);
                        let b = o.dot(d);
                        let disc = b * b - (o.length_squared() - radius * radius);
                        if disc > 0.0 {
                            let t = -b - disc.sqrt();
                            depth[(row * w + col) as usize] =
                                (t / camera.ray_length_factor(row, col)) as f32;
                        }
                    }
                }
                DepthView {
                    camera,
                    depth,
                    rgb: Vec::new(),
                }
            })
            .collect()
    }

    /// 600 isotropic Gaussians (scale 0.02, opacity 0.9) on a Fibonacci sphere of `radius`.
    fn sphere_gaussians(radius: f64) -> OpacityGaussians {
        let n = 600;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let means: Vec<Vec3> = (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - y * y).sqrt();
                let a = golden * i as f64;
                (DVec3::new(r * a.cos(), y, r * a.sin()) * radius).as_vec3()
            })
            .collect();
        OpacityGaussians {
            scales: vec![Vec3::splat(0.02); n],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacities: vec![0.9; n],
            colors: vec![[0.5; 3]; n],
            means,
        }
    }

    /// 1,500 flat discs tangent to a sphere of `radius` (in-plane scale 0.02, 0.0008 along the
    /// normal, opacity 0.9): a template avatar's Gaussians, whose box corners do not leave the
    /// surface.
    fn sphere_discs(radius: f64) -> OpacityGaussians {
        let n = 1500;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let dirs: Vec<DVec3> = (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - y * y).sqrt();
                let a = golden * i as f64;
                DVec3::new(r * a.cos(), y, r * a.sin())
            })
            .collect();
        // The rotation taking local z to the radial direction (w, x, y, z).
        let rotations = dirs
            .iter()
            .map(|d| {
                let q = [1.0 + d.z, -d.y, d.x, 0.0];
                let len = q.iter().map(|c| c * c).sum::<f64>().sqrt();
                if len < 1e-9 {
                    [0.0, 1.0, 0.0, 0.0]
                } else {
                    q.map(|c| (c / len) as f32)
                }
            })
            .collect();
        OpacityGaussians {
            means: dirs.iter().map(|d| (*d * radius).as_vec3()).collect(),
            scales: vec![Vec3::new(0.02, 0.02, 0.0008); n],
            rotations,
            opacities: vec![0.9; n],
            colors: vec![[0.5; 3]; n],
        }
    }

    /// Flat discs on a sphere seen by 5 views around it (the default margin and carving
    /// views): by the default rule the rims hold, so vertices stay on the level set the grazing
    /// views' silhouettes carve (median 0.49 footprints off the sphere); with rims settled,
    /// depth samples and the settled vertices smoothed (`--opacity-field template`) the
    /// median is 0.02 footprints (asserted: under a quarter of the held rule's), the area
    /// within 8% of the sphere's.
    #[test]
    fn flat_discs_settle_onto_the_sphere_with_rims_settled() {
        let radius = 0.3;
        let cams = sphere_rig(DVec3::ZERO, 0.4, 5, (96, 96), 40.0).expect("rig");
        let views = sphere_views(cams, radius);
        let g = sphere_discs(radius);
        let footprint = 1.17 / (48.0 / 20f64.to_radians().tan());
        let run = |rules: DepthRules, options: OpacityOptions| {
            let out = median_depth_mesh(&g, &views, rules, &options, None).expect("mesh");
            let mut err: Vec<f64> = radial_errors(&out.mesh, radius, footprint, -1.0)
                .iter()
                .map(|e| e.abs())
                .collect();
            err.sort_by(f64::total_cmp);
            let area = out.mesh.area() / (4.0 * std::f64::consts::PI * radius * radius);
            (err[err.len() / 2], area)
        };
        let plain = OpacityOptions {
            colors: false,
            ..OpacityOptions::default()
        };
        let (held, _) = run(DepthRules::default(), plain);
        let template = OpacityOptions {
            settle_rims: true,
            smoothing: 10,
            ..plain
        };
        let rules = DepthRules {
            sample_stride: 4,
            ..DepthRules::default()
        };
        let (settled, area) = run(rules, template);
        assert!(
            settled < 0.25 * held && (area - 1.0).abs() < 0.08,
            "median |radial error| rims held {held}, rims settled {settled} footprints; \
             area ratio {area}"
        );
    }

    /// Radial errors of `mesh`'s vertices whose direction has a z above `min_z` (all: -1), in
    /// units of `footprint`, sorted; positive outside the sphere.
    fn radial_errors(mesh: &TriMesh, radius: f64, footprint: f64, min_z: f64) -> Vec<f64> {
        let mut err: Vec<f64> = mesh
            .positions()
            .iter()
            .filter(|p| p.normalize().z > min_z)
            .map(|p| (p.length() - radius) / footprint)
            .collect();
        err.sort_by(f64::total_cmp);
        err
    }

    /// Exact depth maps of a sphere from all around: the silhouettes carve it tightly, so the
    /// mesh lies on the sphere within half a footprint, one closed piece.
    #[test]
    fn sphere_mesh_lies_at_the_median_depth() {
        let radius = 0.3;
        let cams = sphere_rig(DVec3::ZERO, 0.4, 20, (96, 96), 40.0).expect("rig");
        let views = sphere_views(cams, radius);
        let rules = DepthRules {
            margin: 0.5,
            carve_views: 1,
            sample_stride: 0,
            surface: 0.0,
        };
        let options = OpacityOptions {
            colors: false,
            ..OpacityOptions::default()
        };
        let g = sphere_gaussians(radius);
        let out = median_depth_mesh(&g, &views, rules, &options, None).expect("mesh");
        assert_eq!(out.stats.pieces, 1);
        // A footprint at the nearest camera distance (~1.17) at 96 px, 40 degrees: ~9 mm.
        let footprint = 1.17 / (48.0 / 20f64.to_radians().tan());
        let err = radial_errors(&out.mesh, radius, footprint, -1.0);
        let median = err[err.len() / 2];
        let (lo, hi) = (err[0], err[err.len() - 1]);
        assert!(
            median.abs() < 0.5 && lo > -2.0 && hi < 0.5,
            "radial error median {median}, range {lo}..{hi} footprints"
        );
    }

    /// The views of an 80-view rig around the sphere whose direction has a z above `min_z`.
    fn front_cams(min_z: f64) -> Vec<trisplat_geometry::Camera> {
        sphere_rig(DVec3::ZERO, 0.4, 80, (96, 96), 40.0)
            .expect("rig")
            .into_iter()
            .filter(|c| c.position().normalize().z > min_z)
            .collect()
    }

    /// Views of the sphere's front cap only (no silhouette carves its front): the margin's own
    /// level set (`surface` = `margin`, the rule before `surface`) lies ~`margin` footprints in
    /// front of the median depth; settled (`surface` 0, the default) the front vertices lie on
    /// it within half a footprint.
    #[test]
    fn settled_vertices_lie_on_the_median_depth() {
        let radius = 0.3;
        let cams = front_cams(0.8);
        assert!(cams.len() >= 6, "{} views", cams.len());
        let views = sphere_views(cams, radius);
        let options = OpacityOptions {
            colors: false,
            ..OpacityOptions::default()
        };
        let g = sphere_gaussians(radius);
        // A footprint at the front of the sphere (camera distance ~1.17 - 0.3).
        let footprint = 0.87 / (48.0 / 20f64.to_radians().tan());
        let margin = 3.0;
        let mut medians = Vec::new();
        for surface in [0.0, margin] {
            let rules = DepthRules {
                margin,
                carve_views: 2,
                sample_stride: 0,
                surface,
            };
            let out = median_depth_mesh(&g, &views, rules, &options, None).expect("mesh");
            let err = radial_errors(&out.mesh, radius, footprint, 0.9);
            assert!(err.len() > 20, "{} front vertices", err.len());
            medians.push(err[err.len() / 2]);
        }
        assert!(
            medians[0].abs() < 0.5 && medians[1] > 1.5,
            "front radial error, settled {} / margin's level set {} footprints",
            medians[0],
            medians[1]
        );
    }

    /// The settling as written before the queries stopped early: every sample through
    /// [`field_at`] over all the views, in vertex order.
    fn settle_plain(views: &DepthViews, vertices: &[DVec3], normals: &[DVec3]) -> Vec<DVec3> {
        let target = -f64::from(views.rules.surface);
        let reach = f64::from(views.rules.margin - views.rules.surface);
        vertices
            .iter()
            .zip(normals)
            .map(|(&x, &n)| {
                if n == DVec3::ZERO || reach <= 0.0 {
                    return x;
                }
                let Some(fp) = views.footprint(x) else {
                    return x;
                };
                if field_at(views, x + n * (0.5 * fp)).0 == f64::NEG_INFINITY {
                    return x;
                }
                let step = reach * fp / f64::from(SETTLE_SAMPLES);
                let at = |t: f64| field_at(views, x - n * t).0;
                if at(0.0) >= target {
                    return x;
                }
                for i in 1..=SETTLE_SAMPLES {
                    let t = step * f64::from(i);
                    if at(t) >= target {
                        let (mut lo, mut hi) = (t - step, t);
                        for _ in 0..SETTLE_BISECTIONS {
                            let mid = 0.5 * (lo + hi);
                            if at(mid) >= target {
                                hi = mid;
                            } else {
                                lo = mid;
                            }
                        }
                        let t = 0.5 * (lo + hi);
                        let thick =
                            (1..=2).all(|k| at(t + f64::from(k) * 0.5 * reach * fp) >= target);
                        return if thick { x - n * t } else { x };
                    }
                }
                x
            })
            .collect()
    }

    /// The early-stopping query against the plain rule (all views, sorted, the k-th taken), at
    /// levels equal to the field itself and just above it (so a `<` taken for `<=`, or a stop
    /// one view early, fails), at `f64::MIN` (-inf or not), with hints carried from query to
    /// query and hints of views that carve nothing; and [`DepthViews::sides`] (Z-order, one
    /// hint per point) against [`depth_field`].
    #[test]
    fn early_stopping_queries_equal_the_plain_rule() {
        let views = random_views(3);
        let mut state = 17u64;
        let points = random_points(&mut state, 3000);
        let mut ties = [0usize; 2];
        let mut stopped = 0usize;
        for k in [1u16, 2, 3] {
            let rules = carving(k);
            let maps = DepthViews::new(&views, rules).expect("views");
            let mut hint = CarveHint::default();
            for (i, &x) in points.iter().enumerate() {
                let (value, seen) = field_at(&maps, x);
                let mut levels = vec![-0.5, 0.0, 0.3, f64::MIN];
                if value.is_finite() {
                    levels.push(value);
                    levels.push(value.next_up());
                }
                for t in levels {
                    if i % 7 == 0 {
                        // A hint of views chosen at random, carving or not.
                        hint = CarveHint::default();
                        for _ in 0..usize::from(k) {
                            let v = (lcg(&mut state) * views.len() as f64) as u16;
                            if !hint.as_slice().contains(&v) {
                                hint.views[usize::from(hint.len)] = v;
                                hint.len += 1;
                            }
                        }
                    }
                    let (above, got_seen) = maps.at_or_above(x, t, &mut hint);
                    assert_eq!(
                        above,
                        value >= t,
                        "point {i}, k {k}, level {t}: field {value}"
                    );
                    if above {
                        assert_eq!(got_seen, seen, "point {i}, k {k}");
                    } else {
                        assert!(seen);
                        stopped += 1;
                    }
                    if value.is_finite() && t == value {
                        ties[0] += 1;
                    }
                    if value.is_finite() && t == value.next_up() {
                        ties[1] += usize::from(!above);
                    }
                }
            }
            let (value, seen) = depth_field(&maps, &points);
            let order = z_order(&points);
            let mut hints = vec![CarveHint::default(); points.len()];
            for t in [-0.5, 0.2] {
                let (inside, got_seen) = maps.sides(&points, t, &order, &mut hints);
                for i in 0..points.len() {
                    assert_eq!(inside[i], value[i] >= t, "point {i}, k {k}, level {t}");
                    assert_eq!(got_seen[i], seen[i], "point {i}, k {k}");
                }
            }
        }
        assert!(
            ties[0] > 1000 && ties[1] > 1000 && stopped > 1000,
            "{ties:?} {stopped}"
        );
    }

    /// The settling (Z-order, queries stopping early, hints) moves every vertex exactly where
    /// the plain rule does, on the sphere's front cap where thick parts settle and the rim
    /// stays; and the median-depth mesh is the same bit for bit on one thread and on three.
    #[test]
    fn settling_equals_the_plain_rule() {
        let radius = 0.3;
        let cams = front_cams(0.6);
        let views = sphere_views(cams, radius);
        let rules = DepthRules::default();
        let maps = DepthViews::new(&views, rules).expect("views");
        // Vertices around the sphere (front, rim and back), a few footprints off it, with
        // normals near the radial direction.
        let mut state = 5u64;
        let mut vertices = Vec::new();
        let mut normals = Vec::new();
        for _ in 0..30000 {
            let d =
                DVec3::new(lcg(&mut state), lcg(&mut state), lcg(&mut state)) * 2.0 - DVec3::ONE;
            let Some(dir) = d.try_normalize().filter(|d| d.z > 0.85) else {
                continue;
            };
            let off = 0.025 * lcg(&mut state);
            vertices.push(dir * (radius + off));
            let wobble = DVec3::new(lcg(&mut state), lcg(&mut state), lcg(&mut state)) - 0.5;
            normals.push((dir + wobble * 0.3).normalize());
        }
        normals[0] = DVec3::ZERO;
        let got = maps.settle_with(&vertices, &normals, true);
        let want = settle_plain(&maps, &vertices, &normals);
        let moved = got.iter().zip(&vertices).filter(|(a, b)| a != b).count();

        assert!(
            moved > 300 && moved + 300 < vertices.len(),
            "{moved} of {} moved",
            vertices.len()
        );
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            assert_eq!(a.to_array(), b.to_array(), "vertex {i}");
        }

        let options = OpacityOptions {
            colors: false,
            ..OpacityOptions::default()
        };
        let g = sphere_gaussians(radius);
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| median_depth_mesh(&g, &views, rules, &options, None).expect("mesh"))
        };
        let (a, b) = (run(1), run(3));
        assert!(a.mesh.triangle_count() > 100);
        assert_eq!(a.mesh.positions(), b.mesh.positions());
        assert_eq!(a.mesh.triangles(), b.mesh.triangles());
    }
}
