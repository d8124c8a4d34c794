//! Gaussian files in every format `convert` and `deform` read and write: INRIA PLY, SPZ and
//! glTF/GLB with `KHR_gaussian_splatting` (docs/conventions.md §3), chosen by extension.

use std::path::Path;

use trisplat_splat::Axes;
use trisplat_splat::GaussianSet;
use trisplat_splat::gltf_splat::{read_gltf_gaussians, write_gltf_gaussians};
use trisplat_splat::ply::{PlyEncoding, PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::spz::{SpzReadOptions, SpzWriteOptions, read_spz, write_spz};

/// A Gaussian file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum GaussianFormat {
    /// INRIA 3DGS PLY (lossless).
    Ply,
    /// Niantic SPZ (quantised, about 10x smaller).
    Spz,
    /// glTF binary with KHR_gaussian_splatting.
    Glb,
    /// glTF text (base64 buffer) with KHR_gaussian_splatting.
    Gltf,
}

impl GaussianFormat {
    /// The format of `path`'s extension, if it is one.
    #[must_use]
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "ply" => Some(Self::Ply),
            "spz" => Some(Self::Spz),
            "glb" => Some(Self::Glb),
            "gltf" => Some(Self::Gltf),
            _ => None,
        }
    }

    /// The file extension.
    #[must_use]
    pub fn extension(self) -> &'static str {
        match self {
            Self::Ply => "ply",
            Self::Spz => "spz",
            Self::Glb => "glb",
            Self::Gltf => "gltf",
        }
    }
}

/// `--axes`: one of the 16 named conventions, or `none`.
///
/// # Errors
/// An unknown name.
pub fn parse_axes(s: &str) -> Result<SpzAxes, String> {
    if s.eq_ignore_ascii_case("none") {
        Ok(SpzAxes(None))
    } else {
        s.parse::<Axes>().map(|a| SpzAxes(Some(a)))
    }
}

/// The axes the Gaussians are in, for SPZ (`None`: stored as they are).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzAxes(pub Option<Axes>);

/// Options of the Gaussian formats.
#[derive(Debug, Clone, clap::Args)]
pub struct GaussianFormatArgs {
    /// Axes of the Gaussians for SPZ, which stores RUB (x right, y up, z back): the set is
    /// converted on writing and reading. rdf (default): the 3DGS training frame of INRIA
    /// PLYs; rub for Y-up data (glTF templates: the SPZ library calls glTF's frame luf); none
    /// keeps the values (as the SPZ library's ply_to_spz). Names: ldb rdb lub rub ldf rdf luf
    /// ruf lfd rfd lfu rfu lbd rbd lbu rbu.
    #[arg(long, value_name = "AXES", value_parser = parse_axes, default_value = "rdf")]
    pub axes: SpzAxes,
    /// SPZ version written: 3 (gzip, smallest-three rotations; read by every SPZ reader), 2,
    /// or 4 (zstd streams, the reference library's newest).
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u32).range(2..=4))]
    pub spz_version: u32,
}

/// A Gaussian file read, with the SPZ header's anti-aliased flag.
pub struct ReadGaussians {
    /// The Gaussians.
    pub set: GaussianSet,
    /// The SPZ anti-aliased flag (false for other formats).
    pub antialiased: bool,
}

/// Reads the Gaussians of `path` in the format of its extension.
///
/// # Errors
/// An unknown extension or a file that cannot be read as Gaussians (named).
pub fn read_gaussian_file(path: &Path, args: &GaussianFormatArgs) -> anyhow::Result<ReadGaussians> {
    let Some(format) = GaussianFormat::from_path(path) else {
        anyhow::bail!(
            "{}: not a Gaussian file (expected .ply, .spz, .glb or .gltf)",
            path.display()
        );
    };
    Ok(match format {
        GaussianFormat::Ply => ReadGaussians {
            set: read_gaussians(path)?,
            antialiased: false,
        },
        GaussianFormat::Spz => {
            let file = read_spz(path, &SpzReadOptions { axes: args.axes.0 })?;
            ReadGaussians {
                set: file.gaussians,
                antialiased: file.antialiased,
            }
        }
        GaussianFormat::Glb | GaussianFormat::Gltf => ReadGaussians {
            set: read_gltf_gaussians(path)?.gaussians,
            antialiased: false,
        },
    })
}

/// Writes `set` to `path` in the format of its extension, atomically.
///
/// # Errors
/// An extension that is no Gaussian format, a set the format cannot hold (bound Gaussians in
/// SPZ or glTF), a failed write.
pub fn write_gaussian_file(
    path: &Path,
    set: &GaussianSet,
    args: &GaussianFormatArgs,
    antialiased: bool,
    ascii: bool,
) -> anyhow::Result<()> {
    let Some(format) = GaussianFormat::from_path(path) else {
        anyhow::bail!(
            "{}: Gaussians are written as .ply, .spz, .glb or .gltf",
            path.display()
        );
    };
    if set.material().is_some() && format != GaussianFormat::Ply {
        eprintln!(
            "warning: {}: SPZ and glTF have no place for the material attributes (albedo, \
             roughness, reflectance); they are not written (write a .ply to keep them)",
            path.display()
        );
    }
    match format {
        GaussianFormat::Ply => {
            let encoding = if ascii {
                PlyEncoding::Ascii
            } else {
                PlyEncoding::BinaryLittleEndian
            };
            write_gaussians(path, set, &PlyWriteOptions { encoding })?;
        }
        GaussianFormat::Spz => write_spz(
            path,
            set,
            &SpzWriteOptions {
                version: args.spz_version,
                axes: args.axes.0,
                antialiased,
                ..SpzWriteOptions::default()
            },
        )?,
        GaussianFormat::Glb | GaussianFormat::Gltf => write_gltf_gaussians(path, set)?,
    }
    Ok(())
}
