//! The QP solver behind a small trait ([`QpBackend`]), and its Clarabel
//! implementation: built once on the layout's fixed sparsity pattern, its data
//! overwritten in place every SQP iteration (`update_P/q/A/b`; presolve and
//! zero-dropping are off, as updates require).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT,
    SolverStatus, SupportedConeT, ZeroConeT,
};

use super::layout::QpLayout;
use super::riccati::RiccatiBackend;
use super::settings::{MpcError, MpcSettings, QpSolver};

/// Outcome of one QP solve, independent of the solver used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QpStatus {
    /// No QP was solved (e.g. the data were not finite).
    #[default]
    NotRun,
    Solved,
    /// Solved to the solver's reduced accuracy.
    AlmostSolved,
    MaxIterations,
    MaxTime,
    /// Primal infeasibility certificate: cannot happen with the soft
    /// constraints unless the data are broken.
    PrimalInfeasible,
    /// Dual infeasibility (unbounded) certificate: cannot happen with a
    /// positive semidefinite cost unless the data are broken.
    DualInfeasible,
    NumericalError,
    InsufficientProgress,
    /// The backend rejected the data update.
    UpdateFailed,
}

impl QpStatus {
    /// Whether the primal solution may be used.
    pub fn is_usable(self) -> bool {
        matches!(self, QpStatus::Solved | QpStatus::AlmostSolved)
    }
}

impl From<SolverStatus> for QpStatus {
    fn from(s: SolverStatus) -> Self {
        match s {
            SolverStatus::Solved => QpStatus::Solved,
            SolverStatus::AlmostSolved => QpStatus::AlmostSolved,
            SolverStatus::MaxIterations => QpStatus::MaxIterations,
            SolverStatus::MaxTime => QpStatus::MaxTime,
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                QpStatus::PrimalInfeasible
            }
            SolverStatus::DualInfeasible | SolverStatus::AlmostDualInfeasible => {
                QpStatus::DualInfeasible
            }
            SolverStatus::InsufficientProgress => QpStatus::InsufficientProgress,
            SolverStatus::Unsolved => QpStatus::NotRun,
            _ => QpStatus::NumericalError,
        }
    }
}

/// The QP's values on the layout's pattern: min ½wᵀPw + qᵀw s.t. A w + s = b,
/// s ∈ {0}^{n_eq} × ℝ₊^{n_ineq}. `p` and `a` are the `nzval` of the layout's
/// CSC patterns (P upper triangle).
#[derive(Debug, Clone, PartialEq)]
pub struct QpData {
    pub p: Vec<f64>,
    pub q: Vec<f64>,
    pub a: Vec<f64>,
    pub b: Vec<f64>,
}

impl QpData {
    /// All values finite?
    pub fn is_finite(&self) -> bool {
        [&self.p, &self.q, &self.a, &self.b]
            .iter()
            .all(|v| v.iter().all(|x| x.is_finite()))
    }
}

/// Result of [`QpBackend::solve`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QpOutcome {
    pub status: QpStatus,
    pub iterations: u32,
    /// ½wᵀPw + qᵀw at the solution.
    pub objective: f64,
}

/// A QP solver with a fixed sparsity pattern whose values change every call.
pub trait QpBackend {
    /// Overwrites all values (same pattern as at construction).
    fn update(&mut self, data: &QpData) -> Result<(), String>;
    /// Solves the current QP.
    fn solve(&mut self) -> QpOutcome;
    /// Primal solution w of the last solve.
    fn primal(&self) -> &[f64];
    /// Multipliers of the constraint rows (Clarabel's z) of the last solve.
    fn dual(&self) -> &[f64];
}

/// Clarabel, built once.
pub struct ClarabelBackend {
    solver: DefaultSolver<f64>,
}

impl std::fmt::Debug for ClarabelBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClarabelBackend").finish_non_exhaustive()
    }
}

impl ClarabelBackend {
    /// Builds the solver on `layout`'s pattern with `data` as the nominal values
    /// its equilibration is computed from.
    pub fn new(layout: &QpLayout, data: &QpData, settings: &MpcSettings) -> Result<Self, MpcError> {
        Self::with_settings(layout, data, Self::settings(settings)?)
    }

    /// Clarabel's settings for `settings`: no presolve and no zero-dropping
    /// (data updates need the pattern kept), quiet, the MPC's tolerance,
    /// iteration and time limits, refinement and equilibration.
    pub fn settings(settings: &MpcSettings) -> Result<DefaultSettings<f64>, MpcError> {
        let tol = settings.qp_tolerance;
        DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(settings.qp_max_iterations)
            .time_limit(settings.time_budget)
            .tol_gap_abs(tol)
            .tol_gap_rel(tol)
            .tol_feas(tol)
            .iterative_refinement_enable(settings.qp_iterative_refinement)
            .equilibrate_enable(settings.qp_equilibrate)
            .build()
            .map_err(|e| MpcError::QpSetup(e.to_string()))
    }

    /// [`Self::new`] with Clarabel's settings given (e.g. to measure others:
    /// `benches/mpc.rs`'s probe).
    pub fn with_settings(
        layout: &QpLayout,
        data: &QpData,
        s: DefaultSettings<f64>,
    ) -> Result<Self, MpcError> {
        let p = CscMatrix::new(
            layout.p.rows,
            layout.p.cols,
            layout.p.colptr.clone(),
            layout.p.rowval.clone(),
            data.p.clone(),
        );
        let a = CscMatrix::new(
            layout.a.rows,
            layout.a.cols,
            layout.a.colptr.clone(),
            layout.a.rowval.clone(),
            data.a.clone(),
        );
        let cones: [SupportedConeT<f64>; 2] =
            [ZeroConeT(layout.n_eq), NonnegativeConeT(layout.n_ineq)];
        let solver = DefaultSolver::new(&p, &data.q, &a, &data.b, &cones, s)
            .map_err(|e| MpcError::QpSetup(e.to_string()))?;
        if !solver.is_data_update_allowed() {
            return Err(MpcError::QpSetup(
                "Clarabel does not allow data updates with these settings".into(),
            ));
        }
        Ok(Self { solver })
    }
}

impl QpBackend for ClarabelBackend {
    fn update(&mut self, data: &QpData) -> Result<(), String> {
        self.solver.update_P(&data.p).map_err(|e| e.to_string())?;
        self.solver.update_q(&data.q).map_err(|e| e.to_string())?;
        self.solver.update_A(&data.a).map_err(|e| e.to_string())?;
        self.solver.update_b(&data.b).map_err(|e| e.to_string())?;
        Ok(())
    }

    fn solve(&mut self) -> QpOutcome {
        self.solver.solve();
        let s = &self.solver.solution;
        QpOutcome {
            status: s.status.into(),
            iterations: s.iterations,
            objective: s.obj_val,
        }
    }

    fn primal(&self) -> &[f64] {
        &self.solver.solution.x
    }

    fn dual(&self) -> &[f64] {
        &self.solver.solution.z
    }
}

/// The backend `MpcSettings::qp_solver` names, chosen at construction (the
/// default backend of [`super::Mpc`], so a daemon or simulator switches
/// solvers by a setting).
#[derive(Debug)]
#[allow(clippy::large_enum_variant)]
pub enum QpSolverBackend {
    Clarabel(ClarabelBackend),
    Riccati(RiccatiBackend),
}

impl QpSolverBackend {
    /// Builds the backend of `settings.qp_solver` (arguments as
    /// [`ClarabelBackend::new`]).
    pub fn new(layout: &QpLayout, data: &QpData, settings: &MpcSettings) -> Result<Self, MpcError> {
        Ok(match settings.qp_solver {
            QpSolver::Clarabel => Self::Clarabel(ClarabelBackend::new(layout, data, settings)?),
            QpSolver::Riccati => Self::Riccati(RiccatiBackend::new(layout, data, settings)?),
        })
    }
}

impl QpBackend for QpSolverBackend {
    fn update(&mut self, data: &QpData) -> Result<(), String> {
        match self {
            Self::Clarabel(b) => b.update(data),
            Self::Riccati(b) => b.update(data),
        }
    }

    fn solve(&mut self) -> QpOutcome {
        match self {
            Self::Clarabel(b) => b.solve(),
            Self::Riccati(b) => b.solve(),
        }
    }

    fn primal(&self) -> &[f64] {
        match self {
            Self::Clarabel(b) => b.primal(),
            Self::Riccati(b) => b.primal(),
        }
    }

    fn dual(&self) -> &[f64] {
        match self {
            Self::Clarabel(b) => b.dual(),
            Self::Riccati(b) => b.dual(),
        }
    }
}
