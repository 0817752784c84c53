//! The built-in demo scene. (Being written.)
