//! Exit-pupil bounds (stub, being written).
