//! The animation of a run: a glTF clip, a folder or pattern of mesh frames, a weights track
//! driving morph targets or blendshapes, a skeletal clip played on the template's joints.

use std::path::{Path, PathBuf};

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{
    AnimatedTemplate, BlendshapeAnimation, BlendshapeSet, Clip, GltfMorphAnimation, GltfTemplate,
    MeshSequence, WeightsTrack,
};

use super::template::{extension, is_gltf, read_template};
use crate::config::ExtractConfig;
use crate::error::PipelineError;

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

/// The template's label for messages: the animation argument, or the template file.
#[must_use]
pub fn animation_label(config: &ExtractConfig) -> String {
    let own = config
        .animation
        .clone()
        .unwrap_or_else(|| config.template.display().to_string());
    match &config.options.animation.clip_from {
        Some(source) => format!(
            "{own} + clip {} of {} (by joint name)",
            config.options.animation.clip.as_deref().unwrap_or("0"),
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
    if let Some(source) = &o.animation.clip_from {
        return open_retargeted(config, source, targets);
    }
    if let Some(spec) = &config.animation {
        let stored = read_template(&config.template)?;
        let (animation, files) = AnimationSource {
            spec,
            template: &config.template,
            clip: o.animation.clip.as_deref(),
            fps: o.animation.fps,
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
        let g = open_gltf(
            &config.template,
            o.animation.clip.as_deref(),
            o.animation.fps,
        )?;
        let stored = g.rest().clone();
        return Ok((stored, Animation::Gltf(Box::new(g)), Vec::new()));
    }
    if let Some(clip) = &o.animation.clip {
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
    let clip = o
        .animation
        .clip
        .as_deref()
        .map_or(clip, |c| clip_of(Some(c)));
    let motion = GltfTemplate::open(source, &clip)?;
    let template = GltfTemplate::open(&config.template, &Clip::None)?
        .retarget(&motion)?
        .with_fps(o.animation.fps);
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
