//! Diagnosis of disagreement between simulation and measurement.
