//! Attitudes as the gimbal protocol carries them (quaternions, radians) and as people read
//! them (roll, pitch and yaw in degrees), and the frame a yaw is in.
//!
//! Quaternions are `[w, x, y, z]`, Hamilton convention, `[1, 0, 0, 0]` the null rotation.
//! Euler angles are the aerospace sequence (yaw about z, then pitch about y, then roll
//! about x): pitch up and yaw to the right are positive. Every conversion is done in `f64`
//! after scaling the quaternion by its largest component, so that any finite quaternion
//! other than zero gives finite angles: roll and yaw in (−180, 180], pitch in [−90, 90].
//! NaN, an infinite component or the zero quaternion give `None`, never NaN.

use mavstack_dialects::common::{GimbalDeviceFlags, GimbalManagerFlags};

/// Radians to degrees.
const DEG_PER_RAD: f64 = 180.0 / core::f64::consts::PI;

/// Roll, pitch and yaw in degrees.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Euler {
    /// Roll, positive to the right, in (−180, 180].
    pub roll_deg: f32,
    /// Pitch, positive up, in [−90, 90].
    pub pitch_deg: f32,
    /// Yaw, positive to the right, in (−180, 180].
    pub yaw_deg: f32,
}

/// What a gimbal's yaw is measured from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum YawFrame {
    /// The vehicle's heading (yaw 0 looks forward): the gimbal follows the vehicle.
    Vehicle,
    /// North (yaw 0 looks north): the gimbal holds its heading as the vehicle turns.
    Earth,
}

impl YawFrame {
    /// Its name: `vehicle` or `earth`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Vehicle => "vehicle",
            Self::Earth => "earth",
        }
    }

    /// The frame of GIMBAL_DEVICE_ATTITUDE_STATUS (and GIMBAL_DEVICE_SET_ATTITUDE) as its
    /// flags say: YAW_IN_EARTH_FRAME or YAW_IN_VEHICLE_FRAME where one is set; when neither
    /// is (older devices), earth with YAW_LOCK and vehicle without, as common.xml says.
    #[must_use]
    pub const fn of_device(flags: GimbalDeviceFlags) -> Self {
        if flags.contains(GimbalDeviceFlags::YAW_IN_EARTH_FRAME) {
            Self::Earth
        } else if flags.contains(GimbalDeviceFlags::YAW_IN_VEHICLE_FRAME)
            || !flags.contains(GimbalDeviceFlags::YAW_LOCK)
        {
            Self::Vehicle
        } else {
            Self::Earth
        }
    }

    /// The frame a gimbal manager request (DO_GIMBAL_MANAGER_PITCHYAW's param 5,
    /// GIMBAL_MANAGER_SET_PITCHYAW, GIMBAL_MANAGER_SET_ATTITUDE) asks for, by the same rule.
    #[must_use]
    pub const fn of_manager(flags: GimbalManagerFlags) -> Self {
        Self::of_device(GimbalDeviceFlags(flags.0 as u16))
    }

    /// Whether `flags` say explicitly which frame they are in (YAW_IN_EARTH_FRAME or
    /// YAW_IN_VEHICLE_FRAME): only then is a status's `delta_yaw` meaningful.
    #[must_use]
    pub const fn explicit(flags: GimbalDeviceFlags) -> bool {
        flags.contains(GimbalDeviceFlags::YAW_IN_EARTH_FRAME)
            || flags.contains(GimbalDeviceFlags::YAW_IN_VEHICLE_FRAME)
    }
}

/// The quaternion scaled to unit length, in `f64`; `None` for NaN, infinite components or
/// the zero quaternion.
fn unit(q: [f32; 4]) -> Option<[f64; 4]> {
    if q.iter().any(|c| !c.is_finite()) {
        return None;
    }
    // Scaling by the largest component first keeps the squares finite.
    let largest = q.iter().fold(0.0f64, |m, &c| m.max(f64::from(c).abs()));
    if largest == 0.0 {
        return None;
    }
    let s = q.map(|c| f64::from(c) / largest);
    let norm = libm::sqrt(s.iter().map(|c| c * c).sum::<f64>());
    Some(s.map(|c| c / norm))
}

/// Degrees in (−180, 180].
#[must_use]
pub fn wrap_deg(deg: f64) -> f64 {
    if !deg.is_finite() {
        return 0.0;
    }
    let mut d = libm::fmod(deg, 360.0);
    if d > 180.0 {
        d -= 360.0;
    } else if d <= -180.0 {
        d += 360.0;
    }
    d
}

/// The Euler angles of quaternion `q`; `None` when it is not a rotation (a NaN or infinite
/// component, or all zero). Any other quaternion is taken as the rotation it is a multiple
/// of.
#[must_use]
pub fn euler_from_quaternion(q: [f32; 4]) -> Option<Euler> {
    let [w, x, y, z] = unit(q)?;
    let roll = libm::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
    let sin_pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0);
    let pitch = libm::asin(sin_pitch);
    let yaw = libm::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
    Some(Euler {
        roll_deg: wrap_deg(roll * DEG_PER_RAD) as f32,
        pitch_deg: (pitch * DEG_PER_RAD).clamp(-90.0, 90.0) as f32,
        yaw_deg: wrap_deg(yaw * DEG_PER_RAD) as f32,
    })
}

/// The quaternion of roll, pitch and yaw in degrees (non-finite angles count as 0).
#[must_use]
pub fn quaternion_from_euler(roll_deg: f32, pitch_deg: f32, yaw_deg: f32) -> [f32; 4] {
    let half = |deg: f32| {
        let d = if deg.is_finite() { f64::from(deg) } else { 0.0 };
        d / DEG_PER_RAD / 2.0
    };
    let (sr, cr) = libm::sincos(half(roll_deg));
    let (sp, cp) = libm::sincos(half(pitch_deg));
    let (sy, cy) = libm::sincos(half(yaw_deg));
    [
        (cr * cp * cy + sr * sp * sy) as f32,
        (sr * cp * cy - cr * sp * sy) as f32,
        (cr * sp * cy + sr * cp * sy) as f32,
        (cr * cp * sy - sr * sp * cy) as f32,
    ]
}

/// A gimbal device's attitude (GIMBAL_DEVICE_ATTITUDE_STATUS) in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Attitude {
    /// Roll, pitch and yaw; the yaw in [`frame`](Self::frame).
    pub euler: Euler,
    /// What the status's yaw is measured from, as its flags say.
    pub frame: YawFrame,
    /// The yaw from the vehicle's heading: the status's own in the vehicle frame, or
    /// computed from its `delta_yaw` when it is in the earth frame and says so explicitly;
    /// `None` when neither.
    pub yaw_vehicle_deg: Option<f32>,
    /// The yaw from north, the same way round.
    pub yaw_earth_deg: Option<f32>,
    /// Angular rates (roll, pitch, yaw) in degrees per second, each `None` where unknown.
    pub rates_dps: [Option<f32>; 3],
    /// GIMBAL_DEVICE_ERROR_FLAGS bits.
    pub failure_flags: u32,
}

impl Attitude {
    /// The attitude a GIMBAL_DEVICE_ATTITUDE_STATUS reports; `None` when its quaternion is
    /// not a rotation.
    #[must_use]
    pub fn from_status(
        status: &mavstack_dialects::common::GimbalDeviceAttitudeStatus,
    ) -> Option<Self> {
        let euler = euler_from_quaternion(status.q)?;
        let frame = YawFrame::of_device(status.flags);
        let delta = (YawFrame::explicit(status.flags) && status.delta_yaw.is_finite())
            .then(|| f64::from(status.delta_yaw) * DEG_PER_RAD);
        let own = Some(euler.yaw_deg);
        let other = delta.map(|d| {
            let yaw = f64::from(euler.yaw_deg);
            let shifted = match frame {
                YawFrame::Vehicle => yaw + d,
                YawFrame::Earth => yaw - d,
            };
            wrap_deg(shifted) as f32
        });
        let (yaw_vehicle_deg, yaw_earth_deg) = match frame {
            YawFrame::Vehicle => (own, other),
            YawFrame::Earth => (other, own),
        };
        // A rate too large for f32 in degrees is as unknown as NaN.
        let dps = |r: f32| {
            let d = (f64::from(r) * DEG_PER_RAD) as f32;
            d.is_finite().then_some(d)
        };
        Some(Self {
            euler,
            frame,
            yaw_vehicle_deg,
            yaw_earth_deg,
            rates_dps: [
                dps(status.angular_velocity_x),
                dps(status.angular_velocity_y),
                dps(status.angular_velocity_z),
            ],
            failure_flags: status.failure_flags.0,
        })
    }
}

/// Where to look to see `target` from `from` (latitude and longitude in degrees, altitudes
/// in metres above mean sea level): pitch (negative looks down) and yaw from north, in
/// degrees. Over the short distances a gimbal looks, the earth is taken as flat around
/// `from`. A target straight above or below gives yaw 0.
#[must_use]
pub fn look_at(from: (f64, f64, f64), target: (f64, f64, f64)) -> (f32, f32) {
    /// Metres per degree of latitude (WGS-84 mean).
    const M_PER_DEG: f64 = 111_319.49;
    let north = (target.0 - from.0) * M_PER_DEG;
    let east = (target.1 - from.1) * M_PER_DEG * libm::cos(from.0 / DEG_PER_RAD);
    let up = target.2 - from.2;
    let horizontal = libm::sqrt(north * north + east * east);
    let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
    let pitch = finite(libm::atan2(up, horizontal) * DEG_PER_RAD);
    let yaw = if horizontal > 0.0 {
        wrap_deg(libm::atan2(east, north) * DEG_PER_RAD)
    } else {
        0.0
    };
    (pitch as f32, finite(yaw) as f32)
}

/// The property the `gimbal_angles` fuzz target checks, on 16 bytes as four `f32`s: a
/// quaternion whose components are finite and not all zero gives finite angles within
/// their ranges, and the quaternion made from those angles is the same rotation (up to
/// sign) where the input is not near gimbal lock; anything else gives `None`. A status
/// made of the rest of the input gives an attitude exactly when its quaternion is a
/// rotation, with finite angles.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_gimbal_angles(data: &[u8]) {
    use mavstack_core::Message as _;
    use mavstack_dialects::common::GimbalDeviceAttitudeStatus;

    let mut q = [0f32; 4];
    for (i, c) in data.chunks_exact(4).take(4).enumerate() {
        q[i] = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    let valid = q.iter().all(|c| c.is_finite()) && q.iter().any(|&c| c != 0.0);
    let angles = euler_from_quaternion(q);
    assert_eq!(angles.is_some(), valid, "{q:?}");
    if let Some(e) = angles {
        assert!(e.roll_deg.is_finite() && e.pitch_deg.is_finite() && e.yaw_deg.is_finite());
        assert!((-180.0..=180.0).contains(&e.roll_deg), "{e:?}");
        assert!((-90.0..=90.0).contains(&e.pitch_deg), "{e:?}");
        assert!((-180.0..=180.0).contains(&e.yaw_deg), "{e:?}");
        let back = quaternion_from_euler(e.roll_deg, e.pitch_deg, e.yaw_deg);
        assert!(back.iter().all(|c| c.is_finite()));
        if e.pitch_deg.abs() < 80.0 {
            let u = unit(q).unwrap_or([1.0, 0.0, 0.0, 0.0]);
            let dot: f64 = u.iter().zip(back).map(|(a, b)| a * f64::from(b)).sum();
            assert!(dot.abs() > 0.999, "{q:?} -> {e:?} -> {back:?}");
        }
    }
    let status = GimbalDeviceAttitudeStatus::decode(data);
    let attitude = Attitude::from_status(&status);
    let rotation = status.q.iter().all(|c| c.is_finite()) && status.q.iter().any(|&c| c != 0.0);
    assert_eq!(attitude.is_some(), rotation);
    if let Some(a) = attitude {
        let yaws = [a.yaw_vehicle_deg, a.yaw_earth_deg];
        assert!(yaws.iter().flatten().all(|y| (-180.0..=180.0).contains(y)));
        assert!(yaws.iter().any(Option::is_some));
        assert!(a.rates_dps.iter().flatten().all(|r| r.is_finite()));
    }
    let f = |i: usize| {
        let b = data.get(i..i + 8).map_or([0; 8], |s| {
            let mut a = [0u8; 8];
            a.copy_from_slice(s);
            a
        });
        f64::from_le_bytes(b)
    };
    let (pitch, yaw) = look_at((f(0), f(8), f(16)), (f(24), f(32), f(40)));
    assert!(pitch.is_finite() && yaw.is_finite());
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_dialects::common::{GimbalDeviceAttitudeStatus, GimbalDeviceFlags};

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() < 1e-3
    }

    #[test]
    fn level_and_quarter_turns() {
        let e = euler_from_quaternion([1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!((e.roll_deg, e.pitch_deg, e.yaw_deg), (0.0, 0.0, 0.0));
        // A quarter turn to the right about z.
        let h = core::f32::consts::FRAC_1_SQRT_2;
        let e = euler_from_quaternion([h, 0.0, 0.0, h]).unwrap();
        assert!(close(e.yaw_deg, 90.0), "{e:?}");
        // 30° down about y.
        let q = quaternion_from_euler(0.0, -30.0, 0.0);
        let e = euler_from_quaternion(q).unwrap();
        assert!(close(e.pitch_deg, -30.0) && close(e.yaw_deg, 0.0), "{e:?}");
    }

    #[test]
    fn round_trip_and_scaled_quaternions() {
        for &(r, p, y) in &[
            (0.0, -45.0, 120.0),
            (10.0, 20.0, -170.0),
            (-5.0, -89.0, 0.0),
        ] {
            let q = quaternion_from_euler(r, p, y);
            let big = q.map(|c| c * 1e30);
            let e = euler_from_quaternion(big).unwrap();
            assert!(close(e.pitch_deg, p), "{e:?}");
            if p.abs() < 80.0 {
                assert!(close(e.roll_deg, r) && close(e.yaw_deg, y), "{e:?}");
            }
        }
    }

    #[test]
    fn nan_and_zero_are_no_rotation() {
        assert!(euler_from_quaternion([f32::NAN, 0.0, 0.0, 1.0]).is_none());
        assert!(euler_from_quaternion([0.0; 4]).is_none());
        assert!(euler_from_quaternion([f32::INFINITY, 0.0, 0.0, 0.0]).is_none());
        // Tiny but not zero is a rotation: the identity scaled down.
        let e = euler_from_quaternion([1e-40, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(e.pitch_deg, 0.0);
    }

    #[test]
    fn frames_as_the_flags_say() {
        let f = GimbalDeviceFlags;
        assert_eq!(YawFrame::of_device(f(0)), YawFrame::Vehicle);
        assert_eq!(YawFrame::of_device(f(16)), YawFrame::Earth); // YAW_LOCK alone
        assert_eq!(YawFrame::of_device(f(16 | 32)), YawFrame::Vehicle); // explicit wins
        assert_eq!(YawFrame::of_device(f(64)), YawFrame::Earth);
    }

    #[test]
    fn the_other_frame_from_delta_yaw() {
        let mut s = GimbalDeviceAttitudeStatus {
            q: quaternion_from_euler(0.0, -10.0, 30.0),
            flags: GimbalDeviceFlags::YAW_IN_VEHICLE_FRAME,
            delta_yaw: 100f32.to_radians(),
            ..Default::default()
        };
        let a = Attitude::from_status(&s).unwrap();
        assert_eq!(a.frame, YawFrame::Vehicle);
        assert!(close(a.yaw_vehicle_deg.unwrap(), 30.0));
        assert!(close(a.yaw_earth_deg.unwrap(), 130.0));
        // Without an explicit frame flag delta_yaw is ignored.
        s.flags = GimbalDeviceFlags(0);
        let a = Attitude::from_status(&s).unwrap();
        assert_eq!(a.yaw_earth_deg, None);
        // Earth frame, the vehicle heading 170°: 160° from north is -10° from the nose.
        s.flags = GimbalDeviceFlags::YAW_IN_EARTH_FRAME;
        s.q = quaternion_from_euler(0.0, 0.0, 160.0);
        s.delta_yaw = 170f32.to_radians();
        let a = Attitude::from_status(&s).unwrap();
        assert!(close(a.yaw_vehicle_deg.unwrap(), -10.0), "{a:?}");
    }

    #[test]
    fn looking_at_a_point() {
        // 100 m east, 100 m lower: yaw 90, pitch -45.
        let from = (47.0, 8.0, 500.0);
        let east = 100.0 / (111_319.49 * libm::cos(47f64.to_radians()));
        let (p, y) = look_at(from, (47.0, 8.0 + east, 400.0));
        assert!(
            (p + 45.0).abs() < 0.01 && (y - 90.0).abs() < 0.01,
            "{p} {y}"
        );
        let (p, y) = look_at(from, (47.0, 8.0, 400.0));
        assert_eq!((p, y), (-90.0, 0.0));
        let (p, y) = look_at((f64::NAN, 0.0, 0.0), (1.0, 1.0, 1.0));
        assert!(p.is_finite() && y.is_finite());
    }
}
