//! The calibration: the camera parameters `C` (vehicle-interfaces.md section 1), the
//! vehicle's own parameters `V` (section 1.2), and the robot pose.
//!
//! `C` and `V` share one parameter list ([`Param`]) so that every estimator (phase 1's batch,
//! phase 2's filter, the smoother) treats "a parameter to estimate, with a prior" alike: the
//! projection does not depend on `V` (its columns are zero) and the odometry does not depend
//! on `C`.

use nalgebra::{Matrix3, SVector, Vector3};

/// Number of parameters in `C` and `V` together.
pub const N_PARAMS: usize = 14;

/// Number of camera parameters in `C` (the first of [`Param::ALL`]).
pub const N_CAMERA: usize = 10;

/// Every parameter of `C` and `V` as a vector, in [`Param::ALL`] order.
pub type ParamVector = SVector<f64, N_PARAMS>;

/// One parameter of the camera `C` or of the vehicle `V`, any subset of which may be estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Param {
    /// Focal length, pixels (both cameras).
    F,
    /// Principal point column, pixels.
    Cx,
    /// Principal point row, pixels.
    Cy,
    /// Baseline `B`, the camera separation, metres.
    Baseline,
    /// Rig origin in the robot frame, x (forward), metres.
    MountX,
    /// Rig origin in the robot frame, y (left), metres.
    MountY,
    /// Rig origin in the robot frame, z (up), metres.
    MountZ,
    /// Rig roll about robot x, radians.
    MountRoll,
    /// Rig pitch about y, radians; positive tilts the optical axis toward the front.
    MountPitch,
    /// Rig yaw about z, radians.
    MountYaw,
    /// `V`: reported `vx, vy` = `odom_scale` x true (vehicle-interfaces.md 1.2).
    OdomScale,
    /// `V`: reported `vtheta` = `odom_yaw_scale` x true + `odom_yaw_bias`.
    OdomYawScale,
    /// `V`: rad/s added to every reported `vtheta`.
    OdomYawBias,
    /// `V`: seconds; a board timestamp `t` was exposed at odometry-clock time `t - time_offset`.
    TimeOffset,
}

impl Param {
    /// Every parameter of `C` then `V`, in the order of [`ParamVector`].
    pub const ALL: [Self; N_PARAMS] = [
        Self::F,
        Self::Cx,
        Self::Cy,
        Self::Baseline,
        Self::MountX,
        Self::MountY,
        Self::MountZ,
        Self::MountRoll,
        Self::MountPitch,
        Self::MountYaw,
        Self::OdomScale,
        Self::OdomYawScale,
        Self::OdomYawBias,
        Self::TimeOffset,
    ];

    /// The camera's parameters `C` (SUMMARY.json's `camera`).
    pub const CAMERA: [Self; N_CAMERA] = [
        Self::F,
        Self::Cx,
        Self::Cy,
        Self::Baseline,
        Self::MountX,
        Self::MountY,
        Self::MountZ,
        Self::MountRoll,
        Self::MountPitch,
        Self::MountYaw,
    ];

    /// The vehicle's parameters `V` (SUMMARY.json's `vehicle`), in [`Vehicle::to_array`] order.
    pub const VEHICLE: [Self; N_PARAMS - N_CAMERA] = [
        Self::OdomScale,
        Self::OdomYawScale,
        Self::OdomYawBias,
        Self::TimeOffset,
    ];

    /// How a person reads the parameter's value (or sigma): the factor from its SI unit and
    /// the unit's name (`px`, `mm`, `deg`, `%`, `mrad/s`, `ms`).
    pub const fn display_unit(self) -> (f64, &'static str) {
        match self {
            Self::F | Self::Cx | Self::Cy => (1.0, "px"),
            Self::Baseline | Self::MountX | Self::MountY | Self::MountZ => (1e3, "mm"),
            Self::MountRoll | Self::MountPitch | Self::MountYaw => {
                (180.0 / core::f64::consts::PI, "deg")
            }
            Self::OdomScale | Self::OdomYawScale => (100.0, "%"),
            Self::OdomYawBias => (1e3, "mrad/s"),
            Self::TimeOffset => (1e3, "ms"),
        }
    }

    /// A parameter of the vehicle `V` (1.2), not of the camera.
    pub const fn is_vehicle(self) -> bool {
        self.index() >= N_CAMERA
    }

    /// The parameter's name in rig files and summaries (`f`, `cx`, ..., `mount_yaw`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::F => "f",
            Self::Cx => "cx",
            Self::Cy => "cy",
            Self::Baseline => "baseline",
            Self::MountX => "mount_x",
            Self::MountY => "mount_y",
            Self::MountZ => "mount_z",
            Self::MountRoll => "mount_roll",
            Self::MountPitch => "mount_pitch",
            Self::MountYaw => "mount_yaw",
            Self::OdomScale => "odom_scale",
            Self::OdomYawScale => "odom_yaw_scale",
            Self::OdomYawBias => "odom_yaw_bias",
            Self::TimeOffset => "time_offset",
        }
    }

    /// The parameter with this name, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Position in [`ParamVector`].
    pub const fn index(self) -> usize {
        self as usize
    }
}

impl core::fmt::Display for Param {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// An angle wrapped into `(-pi, pi]` (exact for angles already inside).
pub fn wrap_angle(a: f64) -> f64 {
    use core::f64::consts::PI;
    if a > -PI && a <= PI {
        return a;
    }
    let w = a - 2.0 * PI * libm::floor((a + PI) / (2.0 * PI));
    if w <= -PI { w + 2.0 * PI } else { w }
}

/// The rig's pose in the robot frame: `t = (x, y, z)` and `R_RS = Rz(yaw) Ry(pitch) Rx(roll)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Mount {
    /// Forward, metres.
    pub x: f64,
    /// Left, metres.
    pub y: f64,
    /// Up, metres.
    pub z: f64,
    /// Radians about x.
    pub roll: f64,
    /// Radians about y; positive tilts the optical axis toward the robot's front.
    pub pitch: f64,
    /// Radians about z.
    pub yaw: f64,
}

impl Mount {
    /// The head is tilted (pitch or roll beyond 0.05 rad): what makes `f` observable from
    /// planar motion (`selfcal::solver::structural_trap`).
    pub fn is_tilted(&self) -> bool {
        libm::fabs(self.pitch) > 0.05 || libm::fabs(self.roll) > 0.05
    }

    /// `robot_from_rig` rotation `R_RS = Rz(yaw) Ry(pitch) Rx(roll)`.
    pub fn robot_from_rig_rotation(&self) -> Matrix3<f64> {
        rot_z(self.yaw) * rot_y(self.pitch) * rot_x(self.roll)
    }

    /// The rig origin in the robot frame.
    pub fn translation(&self) -> Vector3<f64> {
        Vector3::new(self.x, self.y, self.z)
    }
}

/// The vehicle's own parameters `V` (vehicle-interfaces.md 1.2): how the odometry and the
/// board's clock differ from the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vehicle {
    /// Reported `vx, vy` = `odom_scale` x true.
    pub odom_scale: f64,
    /// Reported `vtheta` = `odom_yaw_scale` x true + `odom_yaw_bias`.
    pub odom_yaw_scale: f64,
    /// Rad/s added to every reported `vtheta`.
    pub odom_yaw_bias: f64,
    /// Seconds: a board timestamp `t` was exposed at odometry-clock time `t - time_offset`.
    pub time_offset: f64,
}

impl Vehicle {
    /// The nominal vehicle: odometry and clock as reported.
    pub const NOMINAL: Self = Self {
        odom_scale: 1.0,
        odom_yaw_scale: 1.0,
        odom_yaw_bias: 0.0,
        time_offset: 0.0,
    };

    /// The true robot-frame velocities from reported ones: `(vx, vy) / odom_scale`,
    /// `(vtheta - odom_yaw_bias) / odom_yaw_scale`.
    pub fn true_velocities(&self, vx: f64, vy: f64, vtheta: f64) -> (f64, f64, f64) {
        (
            vx / self.odom_scale,
            vy / self.odom_scale,
            (vtheta - self.odom_yaw_bias) / self.odom_yaw_scale,
        )
    }

    /// The reported velocities of true ones (the inverse of [`Self::true_velocities`]).
    pub fn reported_velocities(&self, vx: f64, vy: f64, vtheta: f64) -> (f64, f64, f64) {
        (
            vx * self.odom_scale,
            vy * self.odom_scale,
            vtheta * self.odom_yaw_scale + self.odom_yaw_bias,
        )
    }

    /// The odometry-clock time (microseconds, rounded) at which a frame stamped `t_us` by the
    /// board was exposed: `t_us - time_offset` (0 at the earliest).
    pub fn odometry_time_us(&self, t_us: u64) -> u64 {
        let shift = libm::round(self.time_offset * 1e6);
        #[allow(clippy::cast_precision_loss, clippy::cast_possible_truncation)]
        let t = t_us as f64 - shift;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        if t <= 0.0 { 0 } else { t as u64 }
    }

    /// Every parameter, in [`Param::VEHICLE`] order.
    pub const fn to_array(&self) -> [f64; 4] {
        [
            self.odom_scale,
            self.odom_yaw_scale,
            self.odom_yaw_bias,
            self.time_offset,
        ]
    }

    /// Whether every parameter is at its nominal value.
    pub fn is_nominal(&self) -> bool {
        *self == Self::NOMINAL
    }
}

impl Default for Vehicle {
    fn default() -> Self {
        Self::NOMINAL
    }
}

/// The calibration: the camera parameters `C` (shared intrinsics of the two rectified
/// cameras, the baseline and the mount) and the vehicle's parameters `V`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraParams {
    /// Focal length, pixels.
    pub f: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
    /// Camera separation `B`, metres.
    pub baseline: f64,
    /// Rig pose in the robot frame.
    pub mount: Mount,
    /// The vehicle's parameters `V` (odometry scale and bias, clock offset).
    pub vehicle: Vehicle,
}

impl CameraParams {
    /// The value of one parameter.
    pub fn get(&self, p: Param) -> f64 {
        match p {
            Param::F => self.f,
            Param::Cx => self.cx,
            Param::Cy => self.cy,
            Param::Baseline => self.baseline,
            Param::MountX => self.mount.x,
            Param::MountY => self.mount.y,
            Param::MountZ => self.mount.z,
            Param::MountRoll => self.mount.roll,
            Param::MountPitch => self.mount.pitch,
            Param::MountYaw => self.mount.yaw,
            Param::OdomScale => self.vehicle.odom_scale,
            Param::OdomYawScale => self.vehicle.odom_yaw_scale,
            Param::OdomYawBias => self.vehicle.odom_yaw_bias,
            Param::TimeOffset => self.vehicle.time_offset,
        }
    }

    /// Sets one parameter.
    pub fn set(&mut self, p: Param, value: f64) {
        let slot = match p {
            Param::F => &mut self.f,
            Param::Cx => &mut self.cx,
            Param::Cy => &mut self.cy,
            Param::Baseline => &mut self.baseline,
            Param::MountX => &mut self.mount.x,
            Param::MountY => &mut self.mount.y,
            Param::MountZ => &mut self.mount.z,
            Param::MountRoll => &mut self.mount.roll,
            Param::MountPitch => &mut self.mount.pitch,
            Param::MountYaw => &mut self.mount.yaw,
            Param::OdomScale => &mut self.vehicle.odom_scale,
            Param::OdomYawScale => &mut self.vehicle.odom_yaw_scale,
            Param::OdomYawBias => &mut self.vehicle.odom_yaw_bias,
            Param::TimeOffset => &mut self.vehicle.time_offset,
        };
        *slot = value;
    }

    /// All parameters as a vector in [`Param::ALL`] order.
    pub fn to_vector(&self) -> ParamVector {
        ParamVector::from_fn(|i, _| self.get(Param::ALL[i]))
    }

    /// Parameters from a vector in [`Param::ALL`] order.
    pub fn from_vector(v: &ParamVector) -> Self {
        let mut c = Self {
            f: 0.0,
            cx: 0.0,
            cy: 0.0,
            baseline: 0.0,
            mount: Mount::default(),
            vehicle: Vehicle::NOMINAL,
        };
        for (i, p) in Param::ALL.into_iter().enumerate() {
            c.set(p, v[i]);
        }
        c
    }
}

/// A planar robot pose in the world frame (vehicle-interfaces.md section 1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2 {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Heading, radians.
    pub theta: f64,
}

impl Pose2 {
    /// A pose.
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    /// `world_from_robot` rotation `Rz(theta)`.
    pub fn world_from_robot_rotation(&self) -> Matrix3<f64> {
        rot_z(self.theta)
    }

    /// A robot-frame point in the world frame.
    pub fn point_in_world(&self, p_in_robot: &Vector3<f64>) -> Vector3<f64> {
        self.world_from_robot_rotation() * p_in_robot + Vector3::new(self.x, self.y, 0.0)
    }

    /// A world point in the robot frame: `Rz(-theta) (L - (X, Y, 0))`.
    pub fn point_in_robot(&self, p_in_world: &Vector3<f64>) -> Vector3<f64> {
        self.world_from_robot_rotation().transpose()
            * (p_in_world - Vector3::new(self.x, self.y, 0.0))
    }
}

/// Rotation about x.
pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = (libm::sin(a), libm::cos(a));
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Rotation about y.
pub fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = (libm::sin(a), libm::cos(a));
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// Rotation about z.
pub fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = (libm::sin(a), libm::cos(a));
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// The cross-product matrix `[v]x`, so that `[v]x w = v x w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_names_and_indices_agree() {
        for (i, p) in Param::ALL.into_iter().enumerate() {
            assert_eq!(p.index(), i);
            assert_eq!(Param::from_name(p.name()), Some(p));
        }
        for bad in ["", "F", "focal", "yaw", "mount_", "f "] {
            assert_eq!(Param::from_name(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn camera_parameters_round_trip_through_vector_get_and_set() {
        let v = ParamVector::from_fn(|i, _| 0.5 + f64::from(u8::try_from(i).unwrap_or(0)));
        let c = CameraParams::from_vector(&v);
        assert_eq!(c.to_vector(), v);
        for p in Param::ALL {
            assert_eq!(c.get(p), v[p.index()]);
            let mut d = c;
            d.set(p, -7.0);
            assert_eq!(d.get(p), -7.0);
            for q in Param::ALL.into_iter().filter(|q| *q != p) {
                assert_eq!(d.get(q), c.get(q), "setting {p} changed {q}");
            }
        }
    }

    #[test]
    fn rotations_turn_the_right_way() {
        let h = core::f64::consts::FRAC_PI_2;
        let close = |a: Vector3<f64>, b: Vector3<f64>| (a - b).norm() < 1e-15;
        assert!(close(rot_x(h) * Vector3::y(), Vector3::z()));
        assert!(close(rot_y(h) * Vector3::z(), Vector3::x()));
        assert!(close(rot_z(h) * Vector3::x(), Vector3::y()));
        for a in [-3.0, -0.4, 0.0, 0.25, 2.0] {
            for r in [rot_x(a), rot_y(a), rot_z(a)] {
                assert!((r * r.transpose() - Matrix3::identity()).norm() < 1e-15);
                assert!((r.determinant() - 1.0).abs() < 1e-15);
            }
        }
        let (v, w) = (Vector3::new(0.3, -1.2, 2.0), Vector3::new(-0.7, 0.1, 0.9));
        assert!(close(skew(&v) * w, v.cross(&w)));
        let m = Mount {
            roll: 0.1,
            pitch: -0.2,
            yaw: 0.3,
            ..Mount::default()
        };
        assert!(
            (m.robot_from_rig_rotation() - rot_z(0.3) * rot_y(-0.2) * rot_x(0.1)).norm() < 1e-15
        );
    }

    #[test]
    fn pose_transforms_are_inverse() {
        let pose = Pose2::new(3.0, -4.0, 2.5);
        let p = Vector3::new(1.0, 2.0, 3.0);
        assert!((pose.point_in_world(&pose.point_in_robot(&p)) - p).norm() < 1e-12);
        assert!((pose.point_in_robot(&pose.point_in_world(&p)) - p).norm() < 1e-12);
        // Heights are not touched by the planar pose.
        assert_eq!(pose.point_in_world(&p).z, p.z);
    }
}
