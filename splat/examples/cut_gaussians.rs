//! Cuts a small fixture out of a Gaussian PLY with trisplat's own reader and writer:
//! the first `FIRST` Gaussians plus the `EXTREME` Gaussians with the smallest log-scale, in file
//! order.
//!
//! `cargo run -p trisplat-splat --example cut_gaussians -- IN.ply OUT.ply FIRST EXTREME`

use std::path::Path;

use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output, first, extreme] = args.as_slice() else {
        return Err("usage: cut_gaussians IN.ply OUT.ply FIRST EXTREME".into());
    };
    let set = read_gaussians(Path::new(input))?;
    let first: usize = first.parse()?;
    let extreme: usize = extreme.parse()?;
    let mut by_scale: Vec<usize> = (first.min(set.len())..set.len()).collect();
    by_scale.sort_by(|&a, &b| {
        let (la, lb) = (
            set.log_scales()[a].min_element(),
            set.log_scales()[b].min_element(),
        );
        la.total_cmp(&lb).then(a.cmp(&b))
    });
    let mut keep: Vec<usize> = (0..first.min(set.len())).collect();
    keep.extend(by_scale.into_iter().take(extreme));
    keep.sort_unstable();
    let subset = set.select(&keep);
    write_gaussians(Path::new(output), &subset, &PlyWriteOptions::default())?;
    println!("{} of {} Gaussians -> {output}", subset.len(), set.len());
    Ok(())
}
