//! 2DGS surfel rasterization after hbb1's diff-surfel-rasterization (in progress).
