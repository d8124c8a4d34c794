//! Reading a glTF animation clip: the references the `gltf` crate takes on trust checked
//! first, then the channels and their samplers.

use std::path::Path;

use super::model::{Channel, Clip, ClipData, GltfTemplate, Property};
use crate::animation::error::AnimationError;
use crate::animation::sampler::{Interpolation, Sampler};
use crate::io::gltf_data::GltfData;

/// Checks what the `gltf` crate takes on trust in animations (it panics on them): every
/// channel's target path is one of glTF's four and its node and sampler exist, and every
/// sampler's accessors exist.
pub(super) fn check_animation_references(
    path: &Path,
    json: &serde_json::Value,
) -> Result<(), AnimationError> {
    let count = |key: &str| json.get(key).and_then(|v| v.as_array()).map_or(0, Vec::len);
    let (nodes, accessors) = (count("nodes"), count("accessors"));
    let empty = Vec::new();
    let animations = json
        .get("animations")
        .and_then(|a| a.as_array())
        .unwrap_or(&empty);
    for (a, anim) in animations.iter().enumerate() {
        let samplers = anim
            .get("samplers")
            .and_then(|s| s.as_array())
            .unwrap_or(&empty);
        let channels = anim
            .get("channels")
            .and_then(|c| c.as_array())
            .unwrap_or(&empty);
        let fail = |channel: usize, message: String| AnimationError::Animation {
            path: path.to_path_buf(),
            animation: a,
            channel,
            message,
        };
        for (c, channel) in channels.iter().enumerate() {
            let target = channel.get("target");
            let path_name = target.and_then(|t| t.get("path")).and_then(|p| p.as_str());
            if !matches!(
                path_name,
                Some("translation" | "rotation" | "scale" | "weights")
            ) {
                return Err(fail(
                    c,
                    format!(
                        "target path {} is not translation, rotation, scale or weights",
                        path_name.map_or_else(|| "(missing)".to_owned(), |p| format!("{p:?}"))
                    ),
                ));
            }
            match target
                .and_then(|t| t.get("node"))
                .and_then(serde_json::Value::as_u64)
            {
                Some(n) if (n as usize) < nodes => {}
                other => {
                    return Err(fail(
                        c,
                        format!(
                            "targets node {}, but the file has {nodes} nodes",
                            other.map_or_else(|| "(missing)".to_owned(), |n| n.to_string())
                        ),
                    ));
                }
            }
            match channel.get("sampler").and_then(serde_json::Value::as_u64) {
                Some(k) if (k as usize) < samplers.len() => {}
                _ => {
                    return Err(fail(
                        c,
                        format!("its sampler does not exist ({} samplers)", samplers.len()),
                    ));
                }
            }
        }
        for (k, sampler) in samplers.iter().enumerate() {
            for key in ["input", "output"] {
                match sampler.get(key).and_then(serde_json::Value::as_u64) {
                    Some(i) if (i as usize) < accessors => {}
                    _ => {
                        return Err(AnimationError::Animation {
                            path: path.to_path_buf(),
                            animation: a,
                            channel: k,
                            message: format!(
                                "sampler {k}: its {key} accessor does not exist ({accessors} \
                                 accessors)"
                            ),
                        });
                    }
                }
            }
        }
    }
    Ok(())
}
impl GltfTemplate {
    pub(super) fn read_clip(
        &self,
        doc: &gltf::Document,
        buffers: &GltfData,
        clip: &Clip,
    ) -> Result<Option<ClipData>, AnimationError> {
        let not_found = |what: String| AnimationError::ClipNotFound {
            path: self.path.clone(),
            clip: what,
            available: self
                .clip_names
                .iter()
                .enumerate()
                .map(|(i, n)| format!("{i}:{}", n.as_deref().unwrap_or("")))
                .collect::<Vec<_>>()
                .join(", "),
        };
        let anim = match clip {
            Clip::None => return Ok(None),
            Clip::FirstIfAny => match doc.animations().next() {
                Some(a) => a,
                None => return Ok(None),
            },
            Clip::Index(i) => doc
                .animations()
                .nth(*i)
                .ok_or_else(|| not_found(i.to_string()))?,
            Clip::Name(name) => doc
                .animations()
                .find(|a| a.name() == Some(name.as_str()))
                .ok_or_else(|| not_found(format!("{name:?}")))?,
        };
        let a = anim.index();
        let mut channels = Vec::new();
        let mut end = 0.0f64;
        for (c, channel) in anim.channels().enumerate() {
            let err = |message: String| AnimationError::Animation {
                path: self.path.clone(),
                animation: a,
                channel: c,
                message,
            };
            let node = channel.target().node().index();
            let property = match channel.target().property() {
                gltf::animation::Property::Translation => Property::Translation,
                gltf::animation::Property::Rotation => Property::Rotation,
                gltf::animation::Property::Scale => Property::Scale,
                gltf::animation::Property::MorphTargetWeights => Property::Weights,
            };
            let width = match property {
                Property::Translation | Property::Scale => 3,
                Property::Rotation => 4,
                Property::Weights => {
                    let Some(m) = self.nodes[node].mesh else {
                        return Err(err(format!(
                            "animates the weights of node {node}, which has no mesh"
                        )));
                    };
                    self.meshes[m].target_count
                }
            };
            let sampler = channel.sampler();
            let times = buffers.read_dims(&sampler.input(), 1)?;
            let output = sampler.output();
            let values = buffers.read(&output)?;
            let interpolation = Interpolation::from(sampler.interpolation());
            let sampler = Sampler::new(
                times,
                values,
                width,
                interpolation,
                property == Property::Rotation,
            )
            .map_err(err)?;
            end = end.max(sampler.end());
            channels.push(Channel {
                node,
                property,
                sampler,
            });
        }
        Ok(Some(ClipData {
            index: a,
            name: anim.name().map(str::to_string),
            channels,
            end,
        }))
    }
}
