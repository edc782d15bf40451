//! Why a stage refuses a record it was given: what the stage reads of it is missing or not
//! analysable, or the model it runs refuses it. The executor prefixes the record's label.

use crate::physics::error::PhysicsError;
use crate::table::Table;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StageError {
    /// A column the stage reads is not a float column of the record.
    #[error("no float column `{name}`; columns: {columns}")]
    NoColumn { name: String, columns: String },
    /// The record cannot be analysed as it is (too short, not uniformly sampled, ...).
    #[error("{0}")]
    Record(String),
    /// The lag between two records cannot be estimated.
    #[error(transparent)]
    Lag(#[from] crate::signal::sync::LagError),
    /// The model the stage runs refuses the record or its parameters, or stopped.
    #[error(transparent)]
    Physics(#[from] PhysicsError),
    /// The record's figure could not be drawn.
    #[error("drawing the figure: {0}")]
    Figure(#[from] crate::plot::PlotError),
}

/// The float column `name` of `table`, or the error naming the columns it has.
pub fn float_column<'t>(table: &'t Table, name: &str) -> Result<&'t [f64], StageError> {
    table
        .f64_column(name)
        .ok_or_else(|| StageError::NoColumn { name: name.to_string(), columns: table.column_names().join(", ") })
}
