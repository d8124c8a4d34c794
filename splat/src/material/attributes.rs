//! [`Material`]: the physically based attributes of each Gaussian as HRAvatar (CVPR 2025)
//! defines them (docs/conventions.md §3): a linear albedo, a GGX roughness and a Fresnel
//! reflectance at normal incidence (F0), stored activated (each in `0..=1`) as a structure of
//! arrays beside a [`crate::GaussianSet`]'s other parameters.
//!
//! HRAvatar keeps them as sigmoid logits in `attributes_params.pth` (`albedo`, `roughness`,
//! `reflectance`, roughness and reflectance mapped into `[min, max]` ranges); trisplat's PLY files
//! carry the activated values under the names [`PLY_ALBEDO`], [`PLY_ROUGHNESS`] and
//! [`PLY_REFLECTANCE`].

/// Roughness given to Gaussians that have none (HRAvatar's initial value).
pub const DEFAULT_ROUGHNESS: f32 = 0.9;

/// F0 given to Gaussians that have none (HRAvatar's initial value, a dielectric of IOR ≈ 1.5).
pub const DEFAULT_F0: f32 = 0.04;

/// PLY names of the three albedo channels (HRAvatar's `albedo`, one column per channel in the
/// INRIA style of `f_dc_0..2`).
pub const PLY_ALBEDO: [&str; 3] = ["albedo_0", "albedo_1", "albedo_2"];

/// PLY name of the roughness (HRAvatar's `roughness`).
pub const PLY_ROUGHNESS: &str = "roughness";

/// PLY name of F0 (HRAvatar's `reflectance`).
pub const PLY_REFLECTANCE: &str = "reflectance";

/// Material attributes of every Gaussian of a set, one entry per Gaussian in each array, all
/// in `0..=1` (checked by [`crate::GaussianSet::try_new`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Material {
    /// Linear diffuse albedo, RGB.
    pub albedo: Vec<[f32; 3]>,
    /// Perceptual GGX roughness (`α = roughness²`).
    pub roughness: Vec<f32>,
    /// Fresnel reflectance at normal incidence (HRAvatar's `reflectance`), one channel.
    pub f0: Vec<f32>,
}

impl Material {
    /// `n` Gaussians of one albedo, roughness and F0.
    #[must_use]
    pub fn uniform(n: usize, albedo: [f32; 3], roughness: f32, f0: f32) -> Self {
        Self {
            albedo: vec![albedo; n],
            roughness: vec![roughness; n],
            f0: vec![f0; n],
        }
    }

    /// The entries at `indices`, in that order (repeats allowed).
    ///
    /// # Panics
    /// If an index is out of range.
    #[must_use]
    pub fn select(&self, indices: &[usize]) -> Self {
        Self {
            albedo: indices.iter().map(|&i| self.albedo[i]).collect(),
            roughness: indices.iter().map(|&i| self.roughness[i]).collect(),
            f0: indices.iter().map(|&i| self.f0[i]).collect(),
        }
    }

    /// The first Gaussian whose attribute is not finite or outside `0..=1`, with the
    /// attribute's name and value.
    #[must_use]
    pub fn first_out_of_range(&self) -> Option<(usize, &'static str, f32)> {
        let n = self
            .albedo
            .len()
            .min(self.roughness.len())
            .min(self.f0.len());
        (0..n).find_map(|i| self.out_of_range_at(i).map(|(field, v)| (i, field, v)))
    }

    /// Gaussian `i`'s first attribute that is not finite or outside `0..=1`, named, with its
    /// value.
    ///
    /// # Panics
    /// If `i` is out of range.
    #[must_use]
    pub fn out_of_range_at(&self, i: usize) -> Option<(&'static str, f32)> {
        let bad = |v: f32| !(0.0..=1.0).contains(&v);
        if let Some(&v) = self.albedo[i].iter().find(|&&v| bad(v)) {
            return Some(("albedo", v));
        }
        if bad(self.roughness[i]) {
            return Some(("roughness", self.roughness[i]));
        }
        if bad(self.f0[i]) {
            return Some(("reflectance (F0)", self.f0[i]));
        }
        None
    }
}
