//! Animated templates (in progress).
