//! Phase 2 of the method: EKF SLAM with the camera parameters in the state (eq. (3)-(8) of the
//! paper), after phase 1 (`selfcal::solver`) has handed over a calibrated camera, or from the
//! rig's priors when phase 1 is skipped.
//!
//! # Where each equation is
//!
//! Each equation is one named function whose doc comment names it; the vectorised arithmetic
//! they call is in `kernels` and `linalg`.
//!
//! | module | what | equation |
//! |---|---|---|
//! | [`state`] | the state layout [`StateLayout`] (every index into `x` and `P`), the accessors | eq. (3) |
//! | [`predict`] | the pose prediction [`Increment::apply`]; the covariance prediction [`predict::predict_covariance`]; [`Ekf::predict_odometry`] and the other entry points | eq. (4), eq. (5) |
//! | `update` | the gain `K = P H^T S^-1` (`gain`); the state and covariance correction (`correct_state`, `covariance_correction`, Joseph or factored); gating; [`Ekf::update`] | eq. (6), eq. (7) |
//! | [`measurement`] | `H`'s non-zero columns for one landmark, [`measurement_jacobian_columns`]; the dense [`Ekf::measurement_jacobian`] | eq. (8) |
//! | `landmarks` | [`Ekf::add_landmark`] (initialisation with the cross-covariances), [`Ekf::remove_landmark`], [`LandmarkId`] | |
//! | `start` | the constructors from phase 1's hand-over ([`Ekf::from_handover`], [`Ekf::from_batch`]) or the priors ([`Ekf::from_prior`]); the smoother's re-seed [`Ekf::set_joint`] | |
//! | `filter` | [`Ekf`] itself, [`Settings`], [`UpdateReport`] | |
//! | [`motion`] | the motion eq. (4) applies and its noise: the exact arc, [`Increment`] | |
//! | `scale` | each update's correction of the pose and the odometry scale taken in units of the baseline, the covariance with it (`Settings::follow_scale`) | eq. (7) |
//! | [`local`] | local sessions (the compressed filter): updates of a large state on the states near the vehicle, exact, settled when it moves on; [`Ekf::settle`] | eq. (5)-(7) |
//! | `kernels`, `linalg` | the update's arithmetic on column-major slices (multiversioned SIMD loops, faer panels) | eq. (6)-(7) |
//! | [`errors`] | the odometry's errors with memory as states (an option, off by default: it biases the odometry scale) | eq. (4)-(5) |
//! | [`candidates`], [`health`], [`chi2`] | confirmation of new landmarks, the filter's health, chi-square bounds | |
//!
//! # State layout (eq. 3)
//!
//! `x = [X, Y, theta, L_1, ..., L_N, C_est, E]`: the planar pose, each landmark's world
//! point, then the camera parameters listed in the rig file's `estimate` (in that order; the
//! others stay at their start values), and, with [`Settings::odometry_error_states`], the
//! odometry's errors with memory ([`errors`]; no observation involves them). The camera block
//! sits after the landmarks so that every observation's `H` has the same shape (pose, one
//! landmark, camera); a new landmark is inserted before it, and a removed one takes its rows
//! and columns with it (both O(n^2) copies, rare events).
//!
//! The covariance `P` is dense, `n x n` with `n = 3 + 3N + m + e`, in one column-major buffer
//! (nalgebra's `DMatrix`), so that nalgebra and faer can both view it without copying. Only its
//! lower triangle (diagonal included) is maintained: at 500 landmarks `P` is 18 MB, fits in no
//! cache, and the update is bound by memory traffic; mirroring after every update would write
//! the upper half once more (docs/benchmarks.md, "Phase 2 EKF SLAM"). Everything inside reads
//! the lower triangle; [`Ekf::covariance`] hands out the whole, exactly symmetric matrix (a
//! mirrored copy). A large state is updated in local sessions ([`local`]): the update then
//! changes only the states near the vehicle, and the rest of `P` is written out when the
//! vehicle moves on.
//!
//! The world frame is the robot at the first frame (vehicle-interfaces.md section 1): the filter
//! starts at the origin with zero pose covariance, and the first landmarks anchor the map.
//! The camera enters with the hand-over's covariance; a parameter phase 1 held at nominal
//! (variance zero) enters with the rig's prior variance instead, uncorrelated, so that the
//! filter can still learn it if the motion makes it observable.
//!
//! # Prediction (eq. 4-5)
//!
//! The odometry velocities held over each sample's period move the pose along an exact arc,
//! as `rig_model::odometry` integrates them; [`Ekf::predict_odometry`] composes the pieces between
//! two frames into one motion with its covariance ([`Increment`]) and applies it once. The
//! noise is phase 1's: white velocity noise per sample, held with it, so the motion's
//! covariance is `G diag(sv^2, sv^2, sw^2) G^T` with `G` the exact arc Jacobian with respect
//! to the velocities ([`motion`]). Eq. (4) moves the pose, `pose' = pose (+) motion`
//! ([`Increment::apply`]); eq. (5) propagates the covariance, and only the pose rows and columns
//! of `P` change (`P_rr = F P_rr F^T + Q`, `P_rx = F P_rx`, [`predict::predict_covariance`]):
//! O(n), never an `n x n` product.
//!
//! # Update (eq. 6-7, with H of eq. 8) and why it has this form
//!
//! Each landmark gives four measurements `(uL, vL, uR, vR)`; its rows of `H` are non-zero only
//! in the pose, its own landmark and the estimated camera columns (at most 6 + m of them). The
//! update never forms `H`: `A = P H^T` (`n x 4k` for `k` landmarks) is a sum of the few
//! columns of `P` that `H` touches, gathered once, O(n k (6 + m)); `S = H A + R` reads `A` at
//! the same rows. The only O(n^2) step is the covariance update itself, a symmetric low-rank
//! update of the lower triangle.
//!
//! Two algebraically equal forms of that update are implemented ([`CovarianceUpdate`]):
//!
//! * **Joseph**, `P+ = P - K A^T - A K^T + K S K^T`, which for any gain `K` equals
//!   `(I - K H) P (I - K H)^T + K R K^T`: an error in `K` (from an ill-conditioned `S`)
//!   enters `P+` only at second order, and the result is a congruence of `P` plus a positive
//!   term. It is one symmetric rank-`8k` update `P + U M U^T`, `U = [K, A]`,
//!   `M = [[S, -I], [-I, 0]]`, computed as `lower(P) += [K S - A, -K] [K, A]^T`.
//! * **Factored**, `P+ = P - W W^T` with `W = A L^-T` (`S = L L^T`): the optimal-gain form
//!   through the Cholesky factor, rank `4k`, half the multiply-adds and half the memory
//!   traffic of the Joseph form. Its subtraction can in principle lose positive
//!   definiteness when `S` is badly conditioned, which the checks below catch.
//!
//! [`CovarianceUpdate::Auto`] (the default) uses the Joseph form up to
//! [`AUTO_JOSEPH_MAX_STATES`] states (the paper's 19-state filter and maps of over a hundred
//! landmarks) and the factored form above, where the Joseph form's twice the work misses the
//! 500-landmark update's time budget of 5 ms with 10 landmarks in view (the timings of the
//! benches `step_19` and `map_500` are in docs/benchmarks.md, "Phase 2 EKF SLAM"). Both forms
//! stay exact: the tests compare them with the dense textbook update.
//!
//! How the work is organised depends on the size of the state:
//!
//! * **Small states** (up to [`SEQUENTIAL_MAX_STATES`], `P` in the first-level cache): the
//!   accepted landmarks are applied one at a time, each a rank-8 (Joseph) or rank-4 update
//!   with a 4x4 `S`. With the linearisation held at the prior estimate and each innovation
//!   corrected by `H_j dx` for the corrections before it, this is exactly the batch update
//!   (the landmarks' measurement noises are independent), but without the batch's `O(n k^2)`
//!   gain terms, which for the paper's 19 states and 20 measurements are as large as the
//!   rank update itself. The work is done on a copy of `P` padded with zero states to whole
//!   SIMD vectors (a state with no variance and no correlation is left as it is), so that
//!   a failure midway changes nothing. The hot loops are compiled for AVX-512, AVX2 and the
//!   baseline (`multiversion`, chosen at run time under `std`, no reordering of arithmetic).
//! * **Large states**: one batch, the Cholesky factor of the whole `S` (nalgebra), and the
//!   rank update in column panels of the lower triangle: faer's matrix multiply on one thread
//!   (`Par::Seq`) under `std`, nalgebra's gemm without it.
//!
//! Before anything is committed, every diagonal entry of `P+` is computed from the factors
//! (O(n k)) and must stay positive (or stay zero, for the start pose before the first
//! prediction), every Cholesky factorisation must succeed, and the new state must be finite;
//! otherwise the update returns an error and the filter is left exactly as it was (only the
//! health's count of refused updates moves). The pose angle is wrapped into `(-pi, pi]` after
//! each step.
//!
//! # Gating
//!
//! Every landmark's innovation `nu = z - h(x)` (all computed at the same, current estimate) is
//! tested on its own before the batch is formed: its NIS `nu^T S_jj^-1 nu` with its own 4x4
//! block of `S` against the chi-square bound of 4 dof at [`Settings::gate_probability`]
//! (0.999: 18.47). Rejected observations are left out of the batch, reported with their NIS and
//! counted; a landmark rejected [`Settings::max_consecutive_rejections`] times in a row (5) is
//! taken to be false (a wrong association, a reflection) and removed. Gating each landmark
//! alone, rather than the batch, keeps one outlier from vetoing the good observations with it.
//!
//! # Landmark initialisation
//!
//! A new landmark is the stereo triangulation of one measurement at the current pose and camera,
//! `L = g(pose, z, C)`, linearised jointly in all three: with `Gp`, `Gc` and `Gz` the Jacobians
//! of `g` (from `rig_model::rig::Triangulation`; `Gc` restricted to the estimated parameters),
//! `P_LL = G P_qq G^T + Gz R Gz^T` with `G = [Gp, Gc]` over the pose and camera states, and
//! `P_Lx = G P_qx` for every existing state. The cross terms matter: a landmark triangulated
//! with a baseline that is 3 % off is 3 % off in the same direction as every other landmark
//! seen with it, and only the correlation through `C` lets a later update move them together.
//!
//! Later observations of the landmark are linearised at a point of it: by default
//! ([`Settings::follow_points`]) its estimate, moved there before each update that observes it
//! and after each accepted one, with `G`'s heading and camera columns re-linearised at the new
//! point (`P <- T P T^T`, the camera's columns from the pose the landmark was placed from), so
//! that the covariance's unobservable turn of the world and the Jacobians' agree and no update
//! tells the filter its heading from lamps nothing else ties to the map (docs/halls.md, "The
//! linearisation point").
//!
//! # Confirmation
//!
//! [`Candidates`] is the per-frame front door for measurements keyed by the association's track
//! ids: bound tracks update the filter, unbound ones become landmarks only after three
//! consecutive frames whose triangulations agree within a Mahalanobis gate, so clutter never
//! enters the map. See [`candidates`] for the gate's covariance and the retirement of tracks
//! whose landmarks proved false.
//!
//! # Health
//!
//! [`Health`] carries the counters (observations accepted and rejected, landmarks added and
//! removed, updates refused), the mean NIS per degree of freedom over a sliding window of gate
//! outcomes, and a divergence flag: the window mean above its 99.9 % chi-square bound, or any
//! update refused for lost positive definiteness. See [`health`].
//!
//! `#![no_std]` with `alloc`; nothing panics on any input, and NaN or infinite inputs are
//! refused with an error naming them.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

#[cfg(not(feature = "alloc"))]
compile_error!(
    "the vslam-ekf crate needs the `alloc` feature (or `std`): its state grows on the heap"
);

#[cfg(feature = "alloc")]
extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "alloc")]
pub mod candidates;
#[cfg(feature = "alloc")]
pub mod chi2;
#[cfg(feature = "alloc")]
mod error;

pub mod errors;
#[cfg(feature = "alloc")]
mod filter;
#[cfg(feature = "alloc")]
pub mod health;
#[cfg(feature = "alloc")]
mod kernels;
#[cfg(feature = "alloc")]
mod landmarks;
#[cfg(feature = "alloc")]
mod linalg;
#[cfg(feature = "alloc")]
pub mod local;
#[cfg(feature = "alloc")]
mod marginal;
#[cfg(feature = "alloc")]
pub mod measurement;
#[cfg(feature = "alloc")]
pub mod motion;
#[cfg(feature = "alloc")]
pub mod predict;
mod scale;
#[cfg(feature = "alloc")]
mod start;
#[cfg(feature = "alloc")]
pub mod state;
#[cfg(feature = "alloc")]
mod update;

mod views;

#[cfg(feature = "alloc")]
pub use candidates::{CandidateSettings, Candidates, FrameReport};
#[cfg(feature = "alloc")]
pub use error::Error;

pub use errors::ErrorAxis;
#[cfg(feature = "alloc")]
pub use filter::{
    AUTO_JOSEPH_MAX_STATES, CameraUpdate, CovarianceUpdate, Ekf, FEJ_CAMERA_RELATIVE,
    FEJ_POSITION_SIGMA_M, FEJ_PREDICTION_HEADING_SIGMA_RAD, FEJ_SETTLE_SIGMA_M, Gated,
    ITERATE_HEADING_SIGMA_RAD, ITERATE_MAX_PASSES, ITERATE_POSITION_SIGMA_M,
    ITERATE_TOLERANCE_SIGMAS, SEQUENTIAL_MAX_STATES, Settings, UpdateReport,
};
#[cfg(feature = "alloc")]
pub use health::Health;
#[cfg(feature = "alloc")]
pub use landmarks::{LandmarkEstimate, LandmarkId, MERGE_POINT_SIGMA_M};
#[cfg(feature = "alloc")]
pub use measurement::{HColumns, measurement_jacobian_columns};
#[cfg(feature = "alloc")]
pub use motion::Increment;
#[cfg(feature = "alloc")]
pub use start::CameraStart;
#[cfg(feature = "alloc")]
pub use state::{CameraCovariance, LANDMARK_DIM, POSE_DIM, StateLayout};
pub use update::RelativeObservation;
