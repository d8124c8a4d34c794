//! Spatial indexes (in progress).
