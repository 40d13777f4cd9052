//! A small FFI over IPOPT's C interface (`coin/IpStdCInterface.h`, IPOPT 3.11
//! from Debian `coinor-libipopt-dev`), and a safe wrapper that solves any
//! [`Nlp`].
//!
//! Only what the baseline and the min-time problem need: create, set options,
//! solve, free. Callbacks receive the problem through the user-data pointer;
//! a panic inside a callback is caught and reported as an evaluation failure.

use std::ffi::CString;
use std::os::raw::{c_char, c_int, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};

type Number = f64;
type Index = c_int;
type Bool = c_int;
type UserDataPtr = *mut c_void;

#[repr(C)]
struct IpoptProblemInfo {
    _private: [u8; 0],
}
type IpoptProblem = *mut IpoptProblemInfo;

type EvalF = extern "C" fn(Index, *mut Number, Bool, *mut Number, UserDataPtr) -> Bool;
type EvalGradF = extern "C" fn(Index, *mut Number, Bool, *mut Number, UserDataPtr) -> Bool;
type EvalG = extern "C" fn(Index, *mut Number, Bool, Index, *mut Number, UserDataPtr) -> Bool;
type EvalJacG = extern "C" fn(
    Index,
    *mut Number,
    Bool,
    Index,
    Index,
    *mut Index,
    *mut Index,
    *mut Number,
    UserDataPtr,
) -> Bool;
type EvalH = extern "C" fn(
    Index,
    *mut Number,
    Bool,
    Number,
    Index,
    *mut Number,
    Bool,
    Index,
    *mut Index,
    *mut Index,
    *mut Number,
    UserDataPtr,
) -> Bool;

extern "C" {
    fn CreateIpoptProblem(
        n: Index,
        x_l: *mut Number,
        x_u: *mut Number,
        m: Index,
        g_l: *mut Number,
        g_u: *mut Number,
        nele_jac: Index,
        nele_hess: Index,
        index_style: Index,
        eval_f: EvalF,
        eval_g: EvalG,
        eval_grad_f: EvalGradF,
        eval_jac_g: EvalJacG,
        eval_h: EvalH,
    ) -> IpoptProblem;
    fn FreeIpoptProblem(p: IpoptProblem);
    fn AddIpoptStrOption(p: IpoptProblem, keyword: *mut c_char, val: *mut c_char) -> Bool;
    fn AddIpoptNumOption(p: IpoptProblem, keyword: *mut c_char, val: Number) -> Bool;
    fn AddIpoptIntOption(p: IpoptProblem, keyword: *mut c_char, val: c_int) -> Bool;
    fn IpoptSolve(
        p: IpoptProblem,
        x: *mut Number,
        g: *mut Number,
        obj_val: *mut Number,
        mult_g: *mut Number,
        mult_x_l: *mut Number,
        mult_x_u: *mut Number,
        user_data: UserDataPtr,
    ) -> c_int;
}

/// A nonlinear program min f(z) s.t. g_l ≤ g(z) ≤ g_u, z_l ≤ z ≤ z_u with sparse
/// derivatives. Infinite bounds are ±1e20 or beyond.
pub trait Nlp {
    fn n(&self) -> usize;
    fn m(&self) -> usize;
    fn bounds(&self, z_l: &mut [f64], z_u: &mut [f64], g_l: &mut [f64], g_u: &mut [f64]);
    fn objective(&mut self, z: &[f64]) -> Option<f64>;
    fn gradient(&mut self, z: &[f64], grad: &mut [f64]) -> bool;
    fn constraints(&mut self, z: &[f64], g: &mut [f64]) -> bool;
    /// Row and column (0-based) of each Jacobian entry.
    fn jacobian_structure(&self) -> (Vec<usize>, Vec<usize>);
    fn jacobian(&mut self, z: &[f64], values: &mut [f64]) -> bool;
    /// Lower-triangle structure of the Lagrangian's Hessian; `None` for L-BFGS.
    fn hessian_structure(&self) -> Option<(Vec<usize>, Vec<usize>)>;
    /// σ∇²f + Σ λᵢ∇²gᵢ, lower triangle, in the order of the structure.
    fn hessian(&mut self, z: &[f64], sigma: f64, lambda: &[f64], values: &mut [f64]) -> bool;
}

/// IPOPT's return status (`ApplicationReturnStatus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IpoptStatus(pub i32);

impl IpoptStatus {
    /// Solved, or solved to the acceptable level.
    pub fn success(self) -> bool {
        self.0 == 0 || self.0 == 1
    }

    pub fn name(self) -> &'static str {
        match self.0 {
            0 => "Solve_Succeeded",
            1 => "Solved_To_Acceptable_Level",
            2 => "Infeasible_Problem_Detected",
            3 => "Search_Direction_Becomes_Too_Small",
            4 => "Diverging_Iterates",
            5 => "User_Requested_Stop",
            6 => "Feasible_Point_Found",
            -1 => "Maximum_Iterations_Exceeded",
            -2 => "Restoration_Failed",
            -3 => "Error_In_Step_Computation",
            -4 => "Maximum_CpuTime_Exceeded",
            -10 => "Not_Enough_Degrees_Of_Freedom",
            -11 => "Invalid_Problem_Definition",
            -12 => "Invalid_Option",
            -13 => "Invalid_Number_Detected",
            _ => "Internal_Error",
        }
    }
}

/// An option value.
#[derive(Debug, Clone)]
pub enum OptValue {
    Str(String),
    Num(f64),
    Int(i32),
}

/// The outcome of a solve.
#[derive(Debug, Clone)]
pub struct IpoptResult {
    pub status: IpoptStatus,
    pub z: Vec<f64>,
    pub objective: f64,
    /// Constraint values at the solution.
    pub g: Vec<f64>,
    /// Wall time of the solve itself (not of waiting for another thread's).
    pub solve_time: std::time::Duration,
}

struct Ctx<'a> {
    nlp: &'a mut dyn Nlp,
    jac_rows: Vec<usize>,
    jac_cols: Vec<usize>,
    hess: Option<(Vec<usize>, Vec<usize>)>,
}

fn with_ctx(user: UserDataPtr, f: impl FnOnce(&mut Ctx) -> bool) -> Bool {
    // SAFETY: `user` is the `&mut Ctx` passed to `IpoptSolve`, alive for the call.
    let ctx = unsafe { &mut *(user as *mut Ctx) };
    match catch_unwind(AssertUnwindSafe(|| f(ctx))) {
        Ok(true) => 1,
        _ => 0,
    }
}

/// # Safety contract of all callbacks
/// IPOPT passes arrays of the documented sizes (n, m, nele_*).
extern "C" fn eval_f(
    n: Index,
    x: *mut Number,
    _new: Bool,
    obj: *mut Number,
    user: UserDataPtr,
) -> Bool {
    with_ctx(user, |c| {
        let z = unsafe { std::slice::from_raw_parts(x, n as usize) };
        match c.nlp.objective(z) {
            Some(v) if v.is_finite() => {
                unsafe { *obj = v };
                true
            }
            _ => false,
        }
    })
}

extern "C" fn eval_grad_f(
    n: Index,
    x: *mut Number,
    _new: Bool,
    grad: *mut Number,
    user: UserDataPtr,
) -> Bool {
    with_ctx(user, |c| {
        let z = unsafe { std::slice::from_raw_parts(x, n as usize) };
        let gr = unsafe { std::slice::from_raw_parts_mut(grad, n as usize) };
        c.nlp.gradient(z, gr)
    })
}

extern "C" fn eval_g(
    n: Index,
    x: *mut Number,
    _new: Bool,
    m: Index,
    g: *mut Number,
    user: UserDataPtr,
) -> Bool {
    with_ctx(user, |c| {
        let z = unsafe { std::slice::from_raw_parts(x, n as usize) };
        let gv = unsafe { std::slice::from_raw_parts_mut(g, m as usize) };
        c.nlp.constraints(z, gv)
    })
}

extern "C" fn eval_jac_g(
    n: Index,
    x: *mut Number,
    _new: Bool,
    _m: Index,
    nele: Index,
    i_row: *mut Index,
    j_col: *mut Index,
    values: *mut Number,
    user: UserDataPtr,
) -> Bool {
    with_ctx(user, |c| {
        let nele = nele as usize;
        if values.is_null() {
            let rows = unsafe { std::slice::from_raw_parts_mut(i_row, nele) };
            let cols = unsafe { std::slice::from_raw_parts_mut(j_col, nele) };
            for k in 0..nele {
                rows[k] = c.jac_rows[k] as Index;
                cols[k] = c.jac_cols[k] as Index;
            }
            true
        } else {
            let z = unsafe { std::slice::from_raw_parts(x, n as usize) };
            let v = unsafe { std::slice::from_raw_parts_mut(values, nele) };
            c.nlp.jacobian(z, v)
        }
    })
}

extern "C" fn eval_h(
    n: Index,
    x: *mut Number,
    _new_x: Bool,
    sigma: Number,
    m: Index,
    lambda: *mut Number,
    _new_lambda: Bool,
    nele: Index,
    i_row: *mut Index,
    j_col: *mut Index,
    values: *mut Number,
    user: UserDataPtr,
) -> Bool {
    with_ctx(user, |c| {
        let nele = nele as usize;
        let Some((hr, hc)) = &c.hess else {
            return false;
        };
        if values.is_null() {
            let rows = unsafe { std::slice::from_raw_parts_mut(i_row, nele) };
            let cols = unsafe { std::slice::from_raw_parts_mut(j_col, nele) };
            for k in 0..nele {
                rows[k] = hr[k] as Index;
                cols[k] = hc[k] as Index;
            }
            true
        } else {
            let z = unsafe { std::slice::from_raw_parts(x, n as usize) };
            let lam = unsafe { std::slice::from_raw_parts(lambda, m as usize) };
            let v = unsafe { std::slice::from_raw_parts_mut(values, nele) };
            c.nlp.hessian(z, sigma, lam, v)
        }
    })
}

/// Debian's IPOPT uses sequential MUMPS, whose initialisation keeps global
/// state: concurrent solves crash ("PB allocation in DMUMPS_LOAD_INIT", then
/// SIGSEGV). Solves are therefore serialised process-wide.
static SOLVER_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Solves `nlp` from `z0` with IPOPT and the given options (print_level 0 and
/// the limited-memory Hessian, when the problem gives none, are set first).
/// Thread-safe: concurrent calls wait for each other (see `SOLVER_LOCK`).
pub fn solve(nlp: &mut dyn Nlp, z0: &[f64], options: &[(&str, OptValue)]) -> IpoptResult {
    let _guard = SOLVER_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let started = std::time::Instant::now();
    let (n, m) = (nlp.n(), nlp.m());
    assert_eq!(z0.len(), n);
    let (mut zl, mut zu) = (vec![0.0; n], vec![0.0; n]);
    let (mut gl, mut gu) = (vec![0.0; m], vec![0.0; m]);
    nlp.bounds(&mut zl, &mut zu, &mut gl, &mut gu);
    let (jac_rows, jac_cols) = nlp.jacobian_structure();
    let hess = nlp.hessian_structure();
    let nele_hess = hess.as_ref().map_or(0, |h| h.0.len());
    let nele_jac = jac_rows.len();
    // SAFETY: arrays have the sizes declared; IPOPT copies them.
    let problem = unsafe {
        CreateIpoptProblem(
            n as Index,
            zl.as_mut_ptr(),
            zu.as_mut_ptr(),
            m as Index,
            gl.as_mut_ptr(),
            gu.as_mut_ptr(),
            nele_jac as Index,
            nele_hess as Index,
            0,
            eval_f,
            eval_g,
            eval_grad_f,
            eval_jac_g,
            eval_h,
        )
    };
    assert!(!problem.is_null(), "CreateIpoptProblem failed");
    let mut all: Vec<(&str, OptValue)> = vec![
        ("print_level", OptValue::Int(0)),
        ("sb", OptValue::Str("yes".into())),
    ];
    if hess.is_none() {
        all.push((
            "hessian_approximation",
            OptValue::Str("limited-memory".into()),
        ));
    }
    all.extend(options.iter().cloned());
    for (key, value) in &all {
        let k = CString::new(*key).expect("option name without NUL");
        // SAFETY: valid C strings; IPOPT copies them.
        let ok = unsafe {
            match value {
                OptValue::Str(s) => {
                    let v = CString::new(s.as_str()).expect("option value without NUL");
                    AddIpoptStrOption(
                        problem,
                        k.as_ptr() as *mut c_char,
                        v.as_ptr() as *mut c_char,
                    )
                }
                OptValue::Num(v) => AddIpoptNumOption(problem, k.as_ptr() as *mut c_char, *v),
                OptValue::Int(v) => AddIpoptIntOption(problem, k.as_ptr() as *mut c_char, *v),
            }
        };
        assert!(ok != 0, "IPOPT rejected option {key} = {value:?}");
    }
    let mut z = z0.to_vec();
    let mut g = vec![0.0; m];
    let mut obj = f64::NAN;
    let mut ctx = Ctx {
        nlp,
        jac_rows,
        jac_cols,
        hess,
    };
    // SAFETY: buffers sized n / m; ctx outlives the call.
    let status = unsafe {
        IpoptSolve(
            problem,
            z.as_mut_ptr(),
            g.as_mut_ptr(),
            &mut obj,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            &mut ctx as *mut Ctx as UserDataPtr,
        )
    };
    // SAFETY: created above, freed once.
    unsafe { FreeIpoptProblem(problem) };
    IpoptResult {
        status: IpoptStatus(status),
        z,
        objective: obj,
        g,
        solve_time: started.elapsed(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// HS071, the example of IPOPT's documentation: optimum f* = 17.014.
    struct Hs071;

    impl Nlp for Hs071 {
        fn n(&self) -> usize {
            4
        }
        fn m(&self) -> usize {
            2
        }
        fn bounds(&self, zl: &mut [f64], zu: &mut [f64], gl: &mut [f64], gu: &mut [f64]) {
            zl.fill(1.0);
            zu.fill(5.0);
            gl.copy_from_slice(&[25.0, 40.0]);
            gu.copy_from_slice(&[2e19, 40.0]);
        }
        fn objective(&mut self, x: &[f64]) -> Option<f64> {
            Some(x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2])
        }
        fn gradient(&mut self, x: &[f64], g: &mut [f64]) -> bool {
            g[0] = x[0] * x[3] + x[3] * (x[0] + x[1] + x[2]);
            g[1] = x[0] * x[3];
            g[2] = x[0] * x[3] + 1.0;
            g[3] = x[0] * (x[0] + x[1] + x[2]);
            true
        }
        fn constraints(&mut self, x: &[f64], g: &mut [f64]) -> bool {
            g[0] = x[0] * x[1] * x[2] * x[3];
            g[1] = x.iter().map(|v| v * v).sum();
            true
        }
        fn jacobian_structure(&self) -> (Vec<usize>, Vec<usize>) {
            (vec![0, 0, 0, 0, 1, 1, 1, 1], vec![0, 1, 2, 3, 0, 1, 2, 3])
        }
        fn jacobian(&mut self, x: &[f64], v: &mut [f64]) -> bool {
            v[..4].copy_from_slice(&[
                x[1] * x[2] * x[3],
                x[0] * x[2] * x[3],
                x[0] * x[1] * x[3],
                x[0] * x[1] * x[2],
            ]);
            for i in 0..4 {
                v[4 + i] = 2.0 * x[i];
            }
            true
        }
        fn hessian_structure(&self) -> Option<(Vec<usize>, Vec<usize>)> {
            None
        }
        fn hessian(&mut self, _: &[f64], _: f64, _: &[f64], _: &mut [f64]) -> bool {
            false
        }
    }

    #[test]
    fn solves_hs071_with_lbfgs() {
        let r = solve(
            &mut Hs071,
            &[1.0, 5.0, 5.0, 1.0],
            &[("tol", OptValue::Num(1e-8))],
        );
        assert!(r.status.success(), "{}", r.status.name());
        assert!((r.objective - 17.014017).abs() < 1e-4, "{}", r.objective);
    }
}
