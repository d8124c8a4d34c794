//! Reading the inputs: the template, its animation, the Gaussians (bound or bound here), the
//! frame range and the ground truth.

use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{
    AnimatedTemplate, BlendshapeAnimation, BlendshapeSet, Clip, GltfMorphAnimation, GltfTemplate,
    MeshSequence, VertexSkinning, WeightsTrack,
};
use trisplat_geometry::cleanup::weld_vertices;
use trisplat_geometry::io::read_mesh;
use trisplat_splat::Convention;
use trisplat_splat::GaussianSet;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::{BindOptions, init_bound};
use trisplat_splat::{DeformMode, Deformer};

use crate::config::{BIND_NORMAL_SCALE, BIND_OPACITY, BIND_TANGENT_SCALE, ExtractConfig, Mode};
use crate::error::PipelineError;
use crate::methods::bounding_sphere;

/// The animation source; glTF kept concrete for `lbs`.
pub enum Animation {
    /// A glTF/GLB clip (skins, morphs, node animation).
    Gltf(Box<GltfTemplate>),
    /// Anything else (frame files, blendshape weights, or the template alone).
    Other(Box<dyn AnimatedTemplate>),
}

impl Animation {
    /// The animation as the common trait.
    #[must_use]
    pub fn get(&self) -> &dyn AnimatedTemplate {
        match self {
            Self::Gltf(g) => g.as_ref(),
            Self::Other(o) => o.as_ref(),
        }
    }
}

/// A template without animation: one frame, the template itself.
struct Still {
    mesh: TriMesh,
}

impl AnimatedTemplate for Still {
    fn frame_count(&self) -> usize {
        1
    }

    fn frame_time(&self, frame: usize) -> Option<f64> {
        (frame == 0).then_some(0.0)
    }

    fn topology(&self) -> &[[u32; 3]] {
        self.mesh.triangles()
    }

    fn rest(&self) -> &TriMesh {
        &self.mesh
    }

    fn frame(
        &self,
        frame: usize,
    ) -> Result<Vec<DVec3>, trisplat_geometry::animation::AnimationError> {
        if frame == 0 {
            Ok(self.mesh.positions().to_vec())
        } else {
            Err(trisplat_geometry::animation::AnimationError::FrameOutOfRange { frame, count: 1 })
        }
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn is_gltf(path: &Path) -> bool {
    matches!(extension(path).as_str(), "gltf" | "glb")
}

/// The template's label for messages: the animation argument, or the template file.
#[must_use]
pub fn animation_label(config: &ExtractConfig) -> String {
    let own = config
        .animation
        .clone()
        .unwrap_or_else(|| config.template.display().to_string());
    match &config.options.clip_from {
        Some(source) => format!(
            "{own} + clip {} of {} (by joint name)",
            config.options.clip.as_deref().unwrap_or("0"),
            source.display()
        ),
        None => own,
    }
}

/// The clip of a `--clip` value: an index when it parses as one, else a name; the first clip
/// without a value.
#[must_use]
pub fn clip_of(clip: Option<&str>) -> Clip {
    match clip {
        None => Clip::Index(0),
        Some(s) => match s.parse::<usize>() {
            Ok(i) => Clip::Index(i),
            Err(_) => Clip::Name(s.to_string()),
        },
    }
}

/// Opens a glTF (parsed once) with `clip` sampled at `fps`; without `clip`, its first clip, or
/// its stored scene when it has none.
///
/// # Errors
/// An unreadable file or a clip it does not have.
fn open_gltf(path: &Path, clip: Option<&str>, fps: f64) -> Result<GltfTemplate, PipelineError> {
    let clip = clip.map_or(Clip::FirstIfAny, |c| clip_of(Some(c)));
    Ok(GltfTemplate::open(path, &clip)?.with_fps(fps))
}

/// Where an animation comes from (`trisplat deform --animation` and `trisplat extract
/// --animation`).
#[derive(Clone, Copy, Debug)]
pub struct AnimationSource<'a> {
    /// The animation argument: a glTF/GLB, a weights JSON, or a folder or pattern of OBJ/PLY
    /// frames.
    pub spec: &'a str,
    /// The template file (a glTF template brings its own morph targets for a weights JSON).
    pub template: &'a Path,
    /// `--clip` (glTF animations only).
    pub clip: Option<&'a str>,
    /// Sampling rate of a glTF clip and frame rate of a sequence.
    pub fps: f64,
    /// Folder of blendshape target meshes, one `.obj`/`.ply` per target (a weights JSON with
    /// an OBJ/PLY template).
    pub targets: Option<&'a Path>,
}

impl AnimationSource<'_> {
    fn bad(&self, path: &Path, problem: impl Into<String>) -> PipelineError {
        PipelineError::BadAnimation {
            path: path.to_path_buf(),
            problem: problem.into(),
        }
    }

    /// Opens the animation and lists the files it reads (never to be overwritten).
    ///
    /// - `.gltf`/`.glb`: its clip (`clip`, default the first) sampled at `fps`; a file without
    ///   animations gives its stored scene as one frame;
    /// - `.json`: LAM/ARKit blendshape weights, driving a glTF template's morph targets by
    ///   name, or with `targets` the `.obj`/`.ply` meshes of that folder (named by file stem;
    ///   the template file itself is skipped when it sits among them);
    /// - anything else: a folder or pattern of OBJ/PLY frames at `fps`.
    ///
    /// # Errors
    /// A bad `fps`; `clip` for a non-glTF animation; `targets` with a glTF template or a
    /// non-JSON animation; a weights file without morph targets; unreadable files (named).
    pub fn open(&self) -> Result<(Animation, Vec<PathBuf>), PipelineError> {
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(PipelineError::BadOption {
                name: "fps",
                value: self.fps,
                expected: "a positive number of frames per second",
            });
        }
        let path = Path::new(self.spec);
        let files = vec![path.to_path_buf()];
        if is_gltf(path) {
            if self.targets.is_some() {
                return Err(self.bad(path, "--targets is for a weights JSON animation"));
            }
            let g = open_gltf(path, self.clip, self.fps)?;
            return Ok((Animation::Gltf(Box::new(g)), files));
        }
        if self.clip.is_some() {
            return Err(self.bad(path, "--clip needs a glTF animation"));
        }
        if extension(path) == "json" {
            return self.open_weights(path, files);
        }
        if self.targets.is_some() {
            return Err(self.bad(path, "--targets is for a weights JSON animation"));
        }
        let sequence = MeshSequence::from_pattern(self.spec)?.with_fps(self.fps);
        let files = sequence.files().to_vec();
        Ok((Animation::Other(Box::new(sequence)), files))
    }

    /// A weights JSON: a glTF template's morph targets, or the meshes of `targets`.
    fn open_weights(
        &self,
        path: &Path,
        mut files: Vec<PathBuf>,
    ) -> Result<(Animation, Vec<PathBuf>), PipelineError> {
        let track = WeightsTrack::read(path)?;
        if is_gltf(self.template) {
            if self.targets.is_some() {
                return Err(self.bad(
                    self.template,
                    "--targets is for an OBJ/PLY neutral template; a glTF template brings its \
                     own morph targets",
                ));
            }
            let g = GltfTemplate::open(self.template, &Clip::None)?;
            let morph = GltfMorphAnimation::new(g, track)?;
            return Ok((Animation::Other(Box::new(morph)), files));
        }
        let Some(dir) = self.targets else {
            return Err(self.bad(
                path,
                "a weights file drives blendshapes: give a glTF template with morph targets, \
                 or an OBJ/PLY template with --targets DIR (one .obj/.ply per target; \
                 `trisplat deform`)",
            ));
        };
        // The neutral may sit among the targets (ICT FaceKit): it is not a target.
        let template_file = self.template.canonicalize().ok();
        let listing = std::fs::read_dir(dir)
            .map_err(|e| self.bad(dir, format!("cannot list the targets folder: {e}")))?;
        let mut targets: Vec<PathBuf> = listing
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| matches!(extension(p).as_str(), "obj" | "ply"))
            .filter(|p| p.canonicalize().ok() != template_file)
            .collect();
        targets.sort();
        if targets.is_empty() {
            return Err(self.bad(dir, "no .obj/.ply target meshes"));
        }
        let set = BlendshapeSet::from_files(self.template, &targets)?;
        files.extend(targets);
        let blend = BlendshapeAnimation::new(set, track)?;
        Ok((Animation::Other(Box::new(blend)), files))
    }
}

/// The template (in world space, see [`read_template`]), its animation and the files they
/// read (never to be overwritten), each file parsed once: without an animation, a glTF
/// template plays its own clip (`clip`, default its first, or its stored scene) and its posed
/// rest is the template; any other template is one still frame. `targets`: blendshape meshes
/// for a weights JSON with an OBJ/PLY template.
///
/// # Errors
/// Unreadable files (named), a bad `fps`, `clip` or `targets` for an animation that has none,
/// a weights file without morph targets.
pub fn open_template_and_animation(
    config: &ExtractConfig,
    targets: Option<&Path>,
) -> Result<(TriMesh, Animation, Vec<PathBuf>), PipelineError> {
    let o = &config.options;
    if let Some(source) = &o.clip_from {
        return open_retargeted(config, source, targets);
    }
    if let Some(spec) = &config.animation {
        let stored = read_template(&config.template)?;
        let (animation, files) = AnimationSource {
            spec,
            template: &config.template,
            clip: o.clip.as_deref(),
            fps: o.fps,
            targets,
        }
        .open()?;
        return Ok((stored, animation, files));
    }
    if let Some(dir) = targets {
        return Err(PipelineError::BadAnimation {
            path: dir.to_path_buf(),
            problem: "--targets needs a weights JSON animation".to_owned(),
        });
    }
    if is_gltf(&config.template) {
        let g = open_gltf(&config.template, o.clip.as_deref(), o.fps)?;
        let stored = g.rest().clone();
        return Ok((stored, Animation::Gltf(Box::new(g)), Vec::new()));
    }
    if let Some(clip) = &o.clip {
        return Err(PipelineError::BadAnimation {
            path: config.template.clone(),
            problem: format!("--clip {clip} needs a glTF template or animation"),
        });
    }
    let mesh = read_template(&config.template)?;
    let still = Still { mesh: mesh.clone() };
    Ok((mesh, Animation::Other(Box::new(still)), Vec::new()))
}

/// `--clip-from`: the clip of `source` retargeted onto the glTF template by joint name,
/// alone (sampled at `--fps`) or under a weights JSON animation (the clip looped over the
/// track's times, the track's morph weights and head pose on top).
///
/// # Errors
/// A template or `source` that is not glTF, another kind of `--animation`, `--targets`, a
/// clip that does not exist or matches no joint (named).
fn open_retargeted(
    config: &ExtractConfig,
    source: &Path,
    targets: Option<&Path>,
) -> Result<(TriMesh, Animation, Vec<PathBuf>), PipelineError> {
    let o = &config.options;
    let bad = |path: &Path, problem: &str| PipelineError::BadAnimation {
        path: path.to_path_buf(),
        problem: problem.to_owned(),
    };
    if !is_gltf(&config.template) {
        return Err(bad(
            &config.template,
            "--clip-from needs a glTF template with joints to play the clip on",
        ));
    }
    if !is_gltf(source) {
        return Err(bad(source, "--clip-from takes a glTF/GLB file with a clip"));
    }
    if let Some(dir) = targets {
        return Err(bad(dir, "--targets is for an OBJ/PLY template"));
    }
    let clip = Clip::Index(0);
    let clip = o.clip.as_deref().map_or(clip, |c| clip_of(Some(c)));
    let motion = GltfTemplate::open(source, &clip)?;
    let template = GltfTemplate::open(&config.template, &Clip::None)?
        .retarget(&motion)?
        .with_fps(o.fps);
    let stored = template.rest().clone();
    let mut files = vec![source.to_path_buf()];
    let animation = match config.animation.as_deref().map(Path::new) {
        None => Animation::Gltf(Box::new(template)),
        Some(track) if extension(track) == "json" => {
            files.push(track.to_path_buf());
            let weights = WeightsTrack::read(track)?;
            Animation::Other(Box::new(GltfMorphAnimation::new(template, weights)?))
        }
        Some(other) => {
            return Err(bad(
                other,
                "--clip-from plays a clip alone or under a weights JSON animation, not with \
                 another animation",
            ));
        }
    };
    Ok((stored, animation, files))
}

/// Reads the template in world space, as the animation evaluates it.
///
/// A glTF/GLB template is its stored scene posed as [`GltfTemplate`] poses it: node transforms,
/// skins and the meshes' default morph weights applied (glTF 2.0: a skinned mesh is placed
/// by its joints and ignores its own node's transform). The static reader
/// ([`read_mesh`], like trimesh) applies the node transform to a skinned mesh instead, which
/// puts a mesh whose node scales it and whose joints scale it back (LAM's `skin.glb`: node
/// scale 0.01) at another scale than every frame of its animation; binding, the
/// scale-derived defaults and `lbs` all need the frames' space. Other formats are read as
/// stored.
///
/// # Errors
/// An unreadable file (named).
pub fn read_template(path: &Path) -> Result<TriMesh, PipelineError> {
    if is_gltf(path) {
        let g = GltfTemplate::open(path, &Clip::None)?;
        return Ok(g.rest().clone());
    }
    Ok(read_mesh(path)?)
}

/// Largest ratio, either way, between the bounding radius of the first frame meshed and that
/// of the template before a run refuses the pair as being at different scales. A pose moves
/// the radius (about the box centre) by far less (CesiumMan's walk: within 5% of its rest
/// pose's); a change of units by far more (cm/m: 100, inch/m: 39.4, mm/m: 1000).
pub const SCALE_MISMATCH: f64 = 10.0;

/// Checks that `frame` (the positions of animation frame `index`, named by `label`) is at the
/// scale of `template` (read from `template_path`): their bounding radii differ by at most
/// [`SCALE_MISMATCH`] either way. The scale-derived defaults (TSDF voxel, alpha) come from the
/// template; frames at another scale would get a voxel or an alpha that many times off.
///
/// # Errors
/// [`PipelineError::ScaleMismatch`]; [`PipelineError::Topology`] for a frame without finite
/// positions.
pub fn check_scale(
    template: &TriMesh,
    template_path: &Path,
    frame: &[DVec3],
    index: usize,
    label: &str,
) -> Result<(), PipelineError> {
    let radius = |vertices: &[DVec3]| bounding_sphere(vertices, &[]).map(|(_, r)| r);
    let (Some(template_radius), Some(frame_radius)) = (radius(template.positions()), radius(frame))
    else {
        return Err(PipelineError::Topology {
            animation: label.to_owned(),
            problem: format!(
                "frame {index} or the template {} has no finite vertex",
                template_path.display()
            ),
        });
    };
    let ratio = frame_radius / template_radius;
    if (1.0 / SCALE_MISMATCH..=SCALE_MISMATCH).contains(&ratio) {
        return Ok(());
    }
    Err(PipelineError::ScaleMismatch {
        animation: label.to_owned(),
        template: template_path.to_path_buf(),
        frame: index,
        frame_radius,
        template_radius,
        ratio,
    })
}

/// Checks that the animation's frames have the vertices and triangles of `template` (read
/// from `template_path`); `label` names the animation.
///
/// # Errors
/// [`PipelineError::Topology`] naming the first difference.
pub fn check_topology(
    template: &TriMesh,
    template_path: &Path,
    anim: &dyn AnimatedTemplate,
    label: &str,
) -> Result<(), PipelineError> {
    let rest = anim.rest();
    let err = |problem: String| PipelineError::Topology {
        animation: label.to_owned(),
        problem,
    };
    if rest.vertex_count() != template.vertex_count() {
        return Err(err(format!(
            "the animation has {} vertices, the template {} has {}",
            rest.vertex_count(),
            template_path.display(),
            template.vertex_count()
        )));
    }
    if rest.triangles() != template.triangles() {
        let first = rest
            .triangles()
            .iter()
            .zip(template.triangles())
            .position(|(x, y)| x != y)
            .unwrap_or(rest.triangle_count().min(template.triangle_count()));
        return Err(err(format!(
            "the animation's triangles differ from those of the template {} (triangle {first}; \
             {} vs {} triangles)",
            template_path.display(),
            rest.triangle_count(),
            template.triangle_count()
        )));
    }
    Ok(())
}

/// Parses `A..B` (B excluded), `A..=B`, `A..`, `..B` or `A` against `count` frames; `None` is
/// every frame.
///
/// # Errors
/// [`PipelineError::Frames`] for a malformed, empty or out-of-range selection.
pub fn parse_frames(spec: Option<&str>, count: usize) -> Result<Range<usize>, PipelineError> {
    let Some(spec) = spec else {
        return Ok(0..count);
    };
    let err = |problem: String| PipelineError::Frames {
        spec: spec.to_owned(),
        problem,
    };
    let num = |s: &str, default: usize| -> Result<usize, PipelineError> {
        let s = s.trim();
        if s.is_empty() {
            Ok(default)
        } else {
            s.parse::<usize>()
                .map_err(|_| err(format!("`{s}` is not a frame number")))
        }
    };
    let range = if let Some((a, b)) = spec.split_once("..=") {
        num(a, 0)?..num(b, usize::MAX)?.saturating_add(1)
    } else if let Some((a, b)) = spec.split_once("..") {
        num(a, 0)?..num(b, count)?
    } else {
        let f = num(spec, 0)?;
        f..f.saturating_add(1)
    };
    if range.start >= range.end {
        return Err(err("the range is empty".to_owned()));
    }
    if range.end > count {
        return Err(err(format!(
            "the animation has {count} frame(s) (0..{count})"
        )));
    }
    Ok(range)
}

/// The deform mode of the library for a pipeline mode (`lbs` bakes its rest pose in binding
/// mode).
#[must_use]
pub fn deform_mode(mode: Mode) -> DeformMode {
    match mode {
        Mode::Jacobian => DeformMode::Jacobian,
        Mode::Binding | Mode::Lbs => DeformMode::Binding,
    }
}

/// Where the Gaussians came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GaussianSource {
    /// Read from this bound file.
    File(PathBuf),
    /// Bound here: this many per triangle.
    Bound(u32),
    /// LAM's per-vertex Gaussians read from this file, bound here around their vertices.
    Lam(PathBuf),
}

/// Reads bound Gaussians from `path` and checks them against `template` (read from
/// `template_path`): they must carry a triangle binding and pass their validity report
/// (finite values, bindings within the template's triangles).
///
/// # Errors
/// An unreadable file, [`PipelineError::NotBound`], [`PipelineError::GaussianIssue`].
pub fn read_bound(
    path: &Path,
    template: &TriMesh,
    template_path: &Path,
) -> Result<GaussianSet, PipelineError> {
    let set = read_gaussians(path)?;
    if set.binding().is_none() {
        return Err(PipelineError::NotBound {
            path: path.to_path_buf(),
        });
    }
    if let Some(issue) = set
        .report(Some(template.triangle_count()))
        .issues
        .into_iter()
        .next()
    {
        return Err(PipelineError::GaussianIssue {
            path: path.to_path_buf(),
            template: template_path.to_path_buf(),
            issue: issue.to_string(),
        });
    }
    Ok(set)
}

/// Checks that `deformer` can deform `set` (bindings within its template, local parameters).
///
/// # Errors
/// [`PipelineError::Gaussians`] naming both files.
pub fn check_set(
    deformer: &Deformer,
    set: &GaussianSet,
    path: &Path,
    template_path: &Path,
) -> Result<(), PipelineError> {
    deformer
        .check(set)
        .map_err(|source| PipelineError::Gaussians {
            path: path.to_path_buf(),
            template: template_path.to_path_buf(),
            cause: source,
        })
}

/// Binds new Gaussians to `template` (read from `template_path`) for `mode`:
/// `per_triangle` per triangle, opaque flat discs (see [`BIND_OPACITY`] and
/// [`BIND_NORMAL_SCALE`]), in the GaussianAvatars convention, or SurFhead's for `jacobian`.
///
/// # Errors
/// [`PipelineError::Bind`] naming the template.
pub fn bind_here(
    template: &TriMesh,
    template_path: &Path,
    mode: Mode,
    per_triangle: u32,
) -> Result<GaussianSet, PipelineError> {
    let convention = if mode == Mode::Jacobian {
        Convention::SurfHead
    } else {
        Convention::GaussianAvatars
    };
    let options = BindOptions {
        per_triangle: per_triangle as usize,
        convention,
        opacity: BIND_OPACITY,
    };
    let set = init_bound(template, &options).map_err(|source| PipelineError::Bind {
        path: template_path.to_path_buf(),
        cause: source,
    })?;
    Ok(flatten(set, convention))
}

/// Multiplies the local scale along the triangle normal by [`BIND_NORMAL_SCALE`] (local y for
/// GaussianAvatars, local z for SurfHead) and in the plane by [`BIND_TANGENT_SCALE`].
fn flatten(set: GaussianSet, convention: Convention) -> GaussianSet {
    let ln = BIND_NORMAL_SCALE.ln();
    let lt = BIND_TANGENT_SCALE.ln();
    let mut parts = set.into_parts();
    for s in &mut parts.log_scales {
        match convention {
            Convention::GaussianAvatars => {
                s.y += ln;
                s.x += lt;
                s.z += lt;
            }
            Convention::SurfHead => {
                s.z += ln;
                s.x += lt;
                s.y += lt;
            }
        }
    }
    // Only finite log-scales were shifted by a finite amount: the set stays valid.
    GaussianSet::new_unchecked(parts)
}

/// The template with its duplicated vertices welded by position (tolerance 0: equal
/// positions; see [`weld_vertices`]).
///
/// glTF (and OBJ) files split a vertex wherever its UV or normal changes, so a closed surface
/// is stored as open patches (CesiumMan: 3,273 vertices, 2,338 positions). Meshing the
/// welded template makes the methods' output watertight wherever the surface is (the
/// incremental Delaunay is watertight whenever its template is). Triangles keep their order,
/// so Gaussian bindings to triangle ids stay valid.
///
/// Each frame of the animation is stored per original vertex; a welded vertex takes the
/// position of its first (lowest-index) original vertex. Duplicates of a seam share their
/// position in the rest pose; where an animation moved them apart (copies skinned or morphed
/// differently), the seam is pinned to the first copy. `lbs` skins a welded vertex with the
/// first copy's weights, for the same reason.
#[derive(Clone, Debug)]
pub struct WeldedTemplate {
    /// The welded template.
    pub mesh: TriMesh,
    /// For each welded vertex, its first original vertex.
    pub first: Vec<u32>,
    /// For each original vertex, its welded vertex.
    pub of_stored: Vec<u32>,
    /// Vertices of the template as stored.
    pub stored_vertices: usize,
}

impl WeldedTemplate {
    /// Welds `template` by position.
    #[must_use]
    pub fn new(template: &TriMesh) -> Self {
        let (mesh, map) = weld_vertices(template, 0.0);
        let mut first = Vec::with_capacity(mesh.vertex_count());
        for (old, &new) in map.iter().enumerate() {
            if new as usize == first.len() {
                first.push(old as u32);
            }
        }
        Self {
            mesh,
            first,
            of_stored: map,
            stored_vertices: template.vertex_count(),
        }
    }

    /// `template` as stored, nothing welded (`trisplat deform` writes Gaussians deformed on
    /// the stored template).
    #[must_use]
    pub fn unwelded(template: &TriMesh) -> Self {
        let n = u32::try_from(template.vertex_count()).unwrap_or(u32::MAX);
        Self {
            mesh: template.clone(),
            first: (0..n).collect(),
            of_stored: (0..n).collect(),
            stored_vertices: template.vertex_count(),
        }
    }

    /// Whether welding merged any vertex.
    #[must_use]
    pub fn merged(&self) -> bool {
        self.first.len() != self.stored_vertices
    }

    /// A frame's positions (one per original vertex) on the welded vertices. `None` when the
    /// frame does not have the stored template's vertex count.
    #[must_use]
    pub fn positions(&self, frame: Vec<DVec3>) -> Option<Vec<DVec3>> {
        if frame.len() != self.stored_vertices {
            return None;
        }
        if !self.merged() {
            return Some(frame);
        }
        Some(self.first.iter().map(|&v| frame[v as usize]).collect())
    }

    /// Skin weights of the original vertices on the welded vertices (each welded vertex takes
    /// its first copy's row). `None` when `skinning` does not have the stored vertex count.
    #[must_use]
    pub fn skinning(&self, skinning: &VertexSkinning) -> Option<VertexSkinning> {
        if skinning.offsets.len() != self.stored_vertices + 1
            || skinning.base_positions.len() != self.stored_vertices
        {
            return None;
        }
        let mut out = VertexSkinning {
            offsets: Vec::with_capacity(self.first.len() + 1),
            palette_len: skinning.palette_len,
            ..VertexSkinning::default()
        };
        out.offsets.push(0);
        for &v in &self.first {
            let v = v as usize;
            let (a, b) = (
                skinning.offsets[v] as usize,
                skinning.offsets[v + 1] as usize,
            );
            out.entries.extend_from_slice(skinning.entries.get(a..b)?);
            out.weights.extend_from_slice(skinning.weights.get(a..b)?);
            out.offsets.push(u32::try_from(out.entries.len()).ok()?);
            out.base_positions.push(skinning.base_positions[v]);
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> TriMesh {
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        TriMesh::new(p, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn self_bound_gaussians_are_flat_along_the_normal() {
        let mesh = square();
        for mode in [Mode::Binding, Mode::Jacobian] {
            let set = bind_here(&mesh, Path::new("square"), mode, 4).expect("bound");
            let world = Deformer::new(&mesh, deform_mode(mode))
                .deform(&set, mesh.positions())
                .expect("deformed");
            for i in 0..world.len() {
                let c = world.covariance(i);
                let normal = c * glam::DVec3::Z;
                let in_plane = c * glam::DVec3::X;
                let (n, t) = (glam::DVec3::Z.dot(normal), glam::DVec3::X.dot(in_plane));
                let ratio = f64::from(BIND_NORMAL_SCALE / BIND_TANGENT_SCALE).powi(2);
                assert!(
                    (n / t - ratio).abs() < 1e-3 * ratio.max(1e-3),
                    "{mode:?} {i}: {n} {t}"
                );
                assert!((world.opacity(i) - BIND_OPACITY).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn welded_template_remaps_frames_and_skinning() {
        // The square with its diagonal's vertices duplicated (a UV seam).
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let stored = TriMesh::new(p.clone(), vec![[0, 1, 2], [3, 4, 5]]);
        let w = WeldedTemplate::new(&stored);
        assert!(w.merged());
        assert_eq!(w.first, vec![0, 1, 2, 5]);
        assert_eq!(w.mesh.triangles(), &[[0, 1, 2], [0, 2, 3]]);
        // A frame where the copies moved apart: the first copy wins.
        let mut frame = p.clone();
        frame[3] = DVec3::splat(9.0);
        let moved = w.positions(frame).expect("six vertices");
        assert_eq!(moved, vec![p[0], p[1], p[2], p[5]]);
        assert!(w.positions(vec![DVec3::ZERO; 5]).is_none());
        // Skin rows of the first copies (vertex v: one influence, palette entry v).
        let skinning = VertexSkinning {
            offsets: (0..=6).collect(),
            entries: (0..6).collect(),
            weights: vec![1.0; 6],
            palette_len: 6,
            base_positions: p.clone(),
        };
        let s = w.skinning(&skinning).expect("six rows");
        assert_eq!(s.offsets, vec![0, 1, 2, 3, 4]);
        assert_eq!(s.entries, vec![0, 1, 2, 5]);
        assert_eq!(s.palette_len, 6);
        assert_eq!(s.base_positions.len(), 4);
        let short = VertexSkinning {
            offsets: vec![0, 1],
            ..skinning
        };
        assert!(w.skinning(&short).is_none());
        // Nothing to weld: frames pass through.
        let single = TriMesh::new(p[..3].to_vec(), vec![[0, 1, 2]]);
        let w = WeldedTemplate::new(&single);
        assert!(!w.merged());
        assert_eq!(
            w.positions(p[..3].to_vec()).expect("three"),
            p[..3].to_vec()
        );
    }

    #[test]
    fn scale_mismatch_is_refused_either_way() {
        let t = square();
        let path = Path::new("t.ply");
        let scaled = |k: f64| -> Vec<DVec3> { t.positions().iter().map(|&p| p * k).collect() };
        for k in [1.0, 0.5, 2.0, 9.9, 1.0 / 9.9] {
            check_scale(&t, path, &scaled(k), 0, "a").expect("same scale");
        }
        for k in [10.5, 100.0, 1.0 / 10.5, 0.01] {
            let e = check_scale(&t, path, &scaled(k), 3, "anim").expect_err("mismatch");
            let PipelineError::ScaleMismatch { frame, ratio, .. } = &e else {
                panic!("{e}");
            };
            assert_eq!(*frame, 3);
            assert!((ratio / k - 1.0).abs() < 1e-5, "{ratio} {k}");
            let text = e.to_string();
            assert!(
                text.starts_with("anim: frame 3 ") && text.contains("t.ply"),
                "{text}"
            );
        }
        // A frame without finite vertices is an error, not a pass.
        let bad = vec![DVec3::NAN; 4];
        assert!(check_scale(&t, path, &bad, 0, "a").is_err());
    }

    #[test]
    fn frame_ranges() {
        assert_eq!(parse_frames(None, 5).expect("all"), 0..5);
        assert_eq!(parse_frames(Some("1..3"), 5).expect("ok"), 1..3);
        assert_eq!(parse_frames(Some("1..=3"), 5).expect("ok"), 1..4);
        assert_eq!(parse_frames(Some("2.."), 5).expect("ok"), 2..5);
        assert_eq!(parse_frames(Some("..2"), 5).expect("ok"), 0..2);
        assert_eq!(parse_frames(Some("4"), 5).expect("ok"), 4..5);
        for bad in ["3..3", "0..9", "x..2", "7", "5.."] {
            let e = parse_frames(Some(bad), 5).expect_err(bad).to_string();
            assert!(e.starts_with(&format!("--frames {bad}: ")), "{e}");
        }
    }
}
