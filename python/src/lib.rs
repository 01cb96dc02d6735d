//! The compiled half of the `poseboard` Python package (`poseboard._native`): thin bindings to
//! the evaluator crate, so that Python gets the numbers the server computes. Argument checking
//! that needs numpy, and the public API with its documentation, live in
//! `python/poseboard/__init__.py`.

mod eval;
mod pose_errors;
mod protocol;

use pyo3::prelude::*;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("EVALUATOR_VERSION", evaluator::report::EVALUATOR_VERSION)?;
    m.add_class::<eval::PyDataset>()?;
    m.add_function(wrap_pyfunction!(eval::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(eval::check_results, m)?)?;
    m.add_function(wrap_pyfunction!(eval::results_csv, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::add, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::adi, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::mssd, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::mspd, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::re, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::te, m)?)?;
    m.add_function(wrap_pyfunction!(pose_errors::vsd, m)?)?;
    m.add_function(wrap_pyfunction!(
        pose_errors::symmetry_transformations_of,
        m
    )?)?;
    Ok(())
}
