//! A mesh's base colour as glTF defines it (material `baseColorFactor` × `baseColorTexture` ×
//! `COLOR_0`), per triangle, for colouring ray-cast hits (docs/conventions.md §5 "Fitting",
//! "Textured targets").
//!
//! Texture coordinates and vertex colours are kept **per triangle corner**, not per vertex:
//! a mesh welded by position (`cleanup::weld_vertices`) merges the copies of a seam vertex that
//! carry different uvs, and the corners keep each side's own. Triangles are in the mesh's
//! order; the colour travels with a [`crate::TriMesh`] ([`crate::TriMesh::with_base_color`])
//! through clones, new positions and welding, and is dropped by operations that change the
//! triangles.
//!
//! The colour at a point ([`BaseColor::rgb_at`]) is in the texture's own encoding (sRGB for a
//! glTF base-colour image), as 3DGS's training images are: the texture is filtered in its
//! stored values ([`crate::texture`]); when the factor or the vertex colours are not white, the
//! filtered value is decoded to linear, multiplied by the factor and the interpolated vertex
//! colour (both linear in glTF), and encoded again. Alpha is ignored.

use std::sync::Arc;

use glam::Vec2;

use crate::color::Rgba;
use crate::texture::{Sampler, Texture, linear_to_srgb, srgb_to_linear};

/// A material's base-colour texture: the decoded image and how it is sampled.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialTexture {
    /// The image (shared by the materials that use it).
    pub texture: Arc<Texture>,
    /// Wrap modes and filter.
    pub sampler: Sampler,
}

/// A material's base colour.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// `baseColorFactor` (linear RGBA; glTF's default is white).
    pub factor: Rgba,
    /// `baseColorTexture`, if any.
    pub texture: Option<MaterialTexture>,
}

impl Default for Material {
    /// glTF's default material: white, no texture.
    fn default() -> Self {
        Self {
            factor: [1.0; 4],
            texture: None,
        }
    }
}

/// Errors building a [`BaseColor`].
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum BaseColorError {
    /// The per-triangle arrays differ in length.
    #[error("{what} has {len} entries for {triangles} triangles")]
    Length {
        /// Which array.
        what: &'static str,
        /// Its length.
        len: usize,
        /// Triangles (the length of the uv corners).
        triangles: usize,
    },
    /// A triangle names a material that does not exist.
    #[error("triangle {triangle} uses material {material}, but there are {count} materials")]
    Material {
        /// Triangle index.
        triangle: usize,
        /// The material index.
        material: u32,
        /// Materials given.
        count: usize,
    },
    /// A corner's uv or colour is NaN or infinite.
    #[error("triangle {triangle} has a non-finite {what}")]
    NonFinite {
        /// Triangle index.
        triangle: usize,
        /// `"uv"` or `"colour"`.
        what: &'static str,
    },
}

/// Base colour per triangle: corner uvs, optional corner colours, a material per triangle.
#[derive(Clone, Debug, PartialEq)]
pub struct BaseColor {
    corner_uvs: Vec<[Vec2; 3]>,
    corner_colors: Option<Vec<[Rgba; 3]>>,
    triangle_material: Vec<u32>,
    materials: Vec<Material>,
}

impl BaseColor {
    /// Per triangle: its corners' uvs (TEXCOORD_0), its corners' colours (COLOR_0; `None` when
    /// no triangle has any), its index into `materials`.
    ///
    /// # Errors
    /// [`BaseColorError`]: arrays of different lengths, a material index out of range, a
    /// non-finite uv or colour.
    pub fn new(
        corner_uvs: Vec<[Vec2; 3]>,
        corner_colors: Option<Vec<[Rgba; 3]>>,
        triangle_material: Vec<u32>,
        materials: Vec<Material>,
    ) -> Result<Self, BaseColorError> {
        let triangles = corner_uvs.len();
        let length = |what, len| BaseColorError::Length {
            what,
            len,
            triangles,
        };
        if triangle_material.len() != triangles {
            return Err(length("triangle_material", triangle_material.len()));
        }
        if let Some(c) = &corner_colors
            && c.len() != triangles
        {
            return Err(length("corner_colors", c.len()));
        }
        for (triangle, &m) in triangle_material.iter().enumerate() {
            if m as usize >= materials.len() {
                return Err(BaseColorError::Material {
                    triangle,
                    material: m,
                    count: materials.len(),
                });
            }
        }
        if let Some(triangle) = corner_uvs
            .iter()
            .position(|c| !c.iter().all(|v| v.is_finite()))
        {
            return Err(BaseColorError::NonFinite {
                triangle,
                what: "uv",
            });
        }
        if let Some(triangle) = corner_colors.as_ref().and_then(|cs| {
            cs.iter()
                .position(|c| !c.iter().flatten().all(|x| x.is_finite()))
        }) {
            return Err(BaseColorError::NonFinite {
                triangle,
                what: "colour",
            });
        }
        Ok(Self {
            corner_uvs,
            corner_colors,
            triangle_material,
            materials,
        })
    }

    /// Number of triangles described.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.corner_uvs.len()
    }

    /// Whether any triangle's material has a texture.
    #[must_use]
    pub fn has_texture(&self) -> bool {
        self.triangle_material
            .iter()
            .any(|&m| self.materials[m as usize].texture.is_some())
    }

    /// The corners' uvs of triangle `t`.
    #[must_use]
    pub fn corner_uvs(&self, t: usize) -> [Vec2; 3] {
        self.corner_uvs[t]
    }

    /// The materials.
    #[must_use]
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// The material of triangle `t`.
    #[must_use]
    pub fn material_of(&self, t: usize) -> &Material {
        &self.materials[self.triangle_material[t] as usize]
    }

    /// The base colour (rgb in `0..=1`, in the texture's encoding; module docs) at the point of
    /// triangle `t` with barycentric `weights` (of its corners, in order).
    ///
    /// # Panics
    /// When `t` is not a triangle of this colour.
    #[must_use]
    pub fn rgb_at(&self, t: usize, weights: [f64; 3]) -> [f32; 3] {
        let material = self.material_of(t);
        let texel = match &material.texture {
            Some(m) => {
                let uvs = self.corner_uvs[t];
                let uv = weights
                    .iter()
                    .zip(uvs)
                    .fold(glam::DVec2::ZERO, |acc, (&w, uv)| acc + uv.as_dvec2() * w)
                    .as_vec2();
                m.texture.sample(uv, m.sampler)
            }
            None => [1.0; 4],
        };
        let mut multiplier = [material.factor[0], material.factor[1], material.factor[2]];
        if let Some(colors) = &self.corner_colors {
            let corners = colors[t];
            #[expect(clippy::cast_possible_truncation, reason = "colours are f32")]
            for (ch, m) in multiplier.iter_mut().enumerate() {
                let c: f64 = (0..3)
                    .map(|k| weights[k] * f64::from(corners[k][ch]))
                    .sum::<f64>();
                *m *= c as f32;
            }
        }
        if multiplier == [1.0; 3] {
            return [texel[0], texel[1], texel[2]].map(|c| c.clamp(0.0, 1.0));
        }
        std::array::from_fn(|ch| {
            let linear = srgb_to_linear(texel[ch].clamp(0.0, 1.0)) * multiplier[ch];
            linear_to_srgb(linear.clamp(0.0, 1.0))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::{Filter, Wrap};

    fn checker() -> Arc<Texture> {
        // 2 x 1: left texel red-ish, right texel blue-ish.
        Arc::new(Texture::new(2, 1, vec![[0.8, 0.2, 0.0, 1.0], [0.0, 0.4, 0.6, 0.5]]).unwrap())
    }

    fn one_triangle(material: Material, colors: Option<[Rgba; 3]>) -> BaseColor {
        let uvs = [
            Vec2::new(0.25, 0.5),
            Vec2::new(0.75, 0.5),
            Vec2::new(0.25, 0.5),
        ];
        BaseColor::new(vec![uvs], colors.map(|c| vec![c]), vec![0], vec![material]).unwrap()
    }

    fn textured(factor: Rgba) -> Material {
        Material {
            factor,
            texture: Some(MaterialTexture {
                texture: checker(),
                sampler: Sampler {
                    wrap_u: Wrap::ClampToEdge,
                    wrap_v: Wrap::ClampToEdge,
                    filter: Filter::Linear,
                },
            }),
        }
    }

    #[test]
    fn white_factor_gives_the_texel_as_stored() {
        let b = one_triangle(textured([1.0; 4]), None);
        assert_eq!(b.rgb_at(0, [1.0, 0.0, 0.0]), [0.8, 0.2, 0.0]);
        assert_eq!(b.rgb_at(0, [0.0, 1.0, 0.0]), [0.0, 0.4, 0.6]);
        // Halfway: the mean of the stored (encoded) values; alpha plays no part.
        let mid = b.rgb_at(0, [0.5, 0.5, 0.0]);
        assert!(
            (mid[0] - 0.4).abs() < 1e-6 && (mid[2] - 0.3).abs() < 1e-6,
            "{mid:?}"
        );
    }

    #[test]
    fn factor_and_vertex_colour_multiply_in_linear() {
        let half = srgb_to_linear(0.5);
        let b = one_triangle(
            textured([0.5, 1.0, 1.0, 1.0]),
            Some([
                [1.0, 1.0, 0.25, 1.0],
                [1.0, 1.0, 0.25, 1.0],
                [1.0, 1.0, 0.25, 1.0],
            ]),
        );
        let c = b.rgb_at(0, [1.0, 0.0, 0.0]);
        let want = [
            linear_to_srgb(srgb_to_linear(0.8) * 0.5),
            0.2,
            linear_to_srgb(0.0),
        ];
        for ch in 0..3 {
            assert!((c[ch] - want[ch]).abs() < 1e-6, "{c:?} vs {want:?}");
        }
        // Without a texture: factor × colour, encoded.
        let plain = one_triangle(
            Material {
                factor: [half, 1.0, 0.0, 1.0],
                texture: None,
            },
            None,
        );
        let c = plain.rgb_at(0, [0.2, 0.3, 0.5]);
        assert!((c[0] - 0.5).abs() < 1e-6, "{c:?}");
        assert!((c[1] - 1.0).abs() < 1e-6 && c[2] == 0.0, "{c:?}");
    }

    #[test]
    fn bad_arrays_are_refused() {
        let uv = [Vec2::ZERO; 3];
        let m = || vec![Material::default()];
        assert!(matches!(
            BaseColor::new(vec![uv; 2], None, vec![0], m()),
            Err(BaseColorError::Length { .. })
        ));
        assert!(matches!(
            BaseColor::new(vec![uv], None, vec![1], m()),
            Err(BaseColorError::Material { .. })
        ));
        let nan = [Vec2::new(f32::NAN, 0.0), Vec2::ZERO, Vec2::ZERO];
        assert!(matches!(
            BaseColor::new(vec![uv, nan], None, vec![0, 0], m()),
            Err(BaseColorError::NonFinite { triangle: 1, .. })
        ));
        assert!(
            !BaseColor::new(vec![uv], None, vec![0], m())
                .unwrap()
                .has_texture()
        );
    }
}
