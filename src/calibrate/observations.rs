//! Observation files (the measured-data contract of `shared/formats/observations.md`).
