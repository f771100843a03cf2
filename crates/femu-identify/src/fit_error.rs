//! Why an identification cannot run or stopped (`FitError`): its own file, below the problems
//! (`fit`, `weighted`, `idic`, `joint`) that all return it.

/// Why an identification cannot run or stopped.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error("no measured point lies in the tissue of the model ({masked} points masked)")]
    NoData { masked: usize },
    #[error("{data} measured components for {free} free parameters: not enough data")]
    TooFewData { data: usize, free: usize },
    #[error(
        "free parameter {name}: bounds [{lower}, {upper}] must be positive with lower < upper"
    )]
    BadBounds {
        name: String,
        lower: f64,
        upper: f64,
    },
    #[error("free parameter {name}: the start {start} is outside its bounds [{lower}, {upper}]")]
    StartOutside {
        name: String,
        start: f64,
        lower: f64,
        upper: f64,
    },
    #[error("the forward solve failed: {0}")]
    Solve(String),
    #[error("sensitivities: {0}")]
    Sensitivity(String),
    #[error("actuator term: {0}")]
    Travel(String),
    #[error("the Jacobian is singular: parameter {name} does not change the measured field (column norm {norm:.3e}); fix it or tie it")]
    Unidentifiable { name: String, norm: f64 },
    /// A joint problem that cannot be set up (see [`crate::joint`]).
    #[error("joint problem: {0}")]
    Joint(String),
    /// The user asked to stop (see [`crate::fit::Problem::with_stop`]).
    #[error("interrupted")]
    Interrupted,
    #[error("measurement covariance: {0}")]
    Covariance(String),
    #[error("speckle shift: {0}")]
    Speckle(String),
}
