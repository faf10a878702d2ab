//! The checks of `leg.toml`: each names the key at fault; gains an MIT motor cannot carry are
//! warned of.

use super::{BusId, DriverKind, Invalid, JointConfig, Kinematics, LegConfig, Ranges, TAU};

impl LegConfig {
    /// Gains an MIT motor carries more than 5% off (its 12-bit kp and kd counts), each with
    /// the key, the value wanted and the value sent. `presrs leg` logs them at start: a leg
    /// spring or damping a count away changes the hop (examples/leg.toml says by how much).
    pub fn quantisation_warnings(&self) -> Vec<String> {
        let imp = &self.impedance;
        let mut out = Vec::new();
        for which in 0..2 {
            let (name, j) = self.joint(which);
            if j.driver != Some(DriverKind::Mit) {
                continue;
            }
            let Some(r) = self.mit_ranges(j) else {
                continue;
            };
            let m = self.map(which);
            let g2 = if which == 0 {
                1.0
            } else {
                let (lo, hi) = self.kinematics.length_range();
                let q = self.kinematics.inverse(0.5 * (lo + hi), 0.0).joints;
                self.kinematics.length_gain(q).powi(2)
            };
            let gains: Vec<(&str, f64, f64)> = if which == 0 {
                vec![
                    (
                        "impedance.hip_stiffness_nm_per_rad",
                        imp.hip_stiffness_nm_per_rad,
                        r.kp_max,
                    ),
                    (
                        "impedance.hip_damping_nm_s_per_rad",
                        imp.hip_damping_nm_s_per_rad,
                        r.kd_max,
                    ),
                ]
            } else {
                vec![
                    (
                        "impedance.stance_stiffness_n_per_m",
                        imp.stance_stiffness_n_per_m,
                        r.kp_max,
                    ),
                    (
                        "impedance.stance_damping_n_s_per_m",
                        imp.stance_damping_n_s_per_m,
                        r.kd_max,
                    ),
                    (
                        "impedance.flight_stiffness_n_per_m",
                        imp.flight_stiffness_n_per_m,
                        r.kp_max,
                    ),
                    (
                        "impedance.flight_damping_n_s_per_m",
                        imp.flight_damping_n_s_per_m,
                        r.kd_max,
                    ),
                ]
            };
            for (key, v, max) in gains {
                let want = m.stiffness_to_driver(v * g2);
                if want <= 0.0 {
                    continue;
                }
                let count = max / 4095.0;
                let sent = (want / count).round() * count;
                if (sent - want).abs() > 0.05 * want {
                    out.push(format!(
                        "{key} = {v}: {name}'s MIT motor gets {sent:.5} for {want:.5} ({:+.0}%: its count is {count:.5}); a gear or screw with more turns per metre or radian makes the count finer",
                        (sent / want - 1.0) * 100.0
                    ));
                }
            }
        }
        out
    }

    /// Every check; the first failure, naming its key.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.foot >= protocol::ids::MAX_FEET {
            return Err(Invalid::range("foot", self.foot, "0..=7"));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz >= 10.0 && self.rate_hz <= 2000.0) {
            return Err(Invalid::range("rate_hz", self.rate_hz, "10..=2000"));
        }
        let period_ms = 1000.0 / self.rate_hz;
        for (key, v) in [
            ("command_timeout_ms", self.command_timeout_ms),
            ("reply_timeout_ms", self.reply_timeout_ms),
        ] {
            if (v as f64) < 2.0 * period_ms || v > 10_000 {
                return Err(Invalid::range(
                    key,
                    v,
                    format!(
                        "at least two periods of rate_hz ({:.1} ms) and at most 10000",
                        2.0 * period_ms
                    ),
                ));
            }
        }
        self.validate_kinematics()?;
        self.validate_impedance()?;
        for which in 0..2 {
            self.validate_joint(which)?;
        }
        self.validate_ids()
    }

    /// The leg's geometry: lengths positive and in order, a two-link knee that can spring.
    fn validate_kinematics(&self) -> Result<(), Invalid> {
        match self.kinematics {
            Kinematics::Prismatic {
                min_length_m,
                max_length_m,
            } => {
                pos("kinematics.min_length_m", min_length_m)?;
                if max_length_m.is_nan() || max_length_m <= min_length_m {
                    return Err(Invalid::range(
                        "kinematics.max_length_m",
                        max_length_m,
                        format!("> min_length_m ({min_length_m})"),
                    ));
                }
            }
            Kinematics::TwoLink {
                thigh_m,
                shank_m,
                knee_sign,
                min_length_m,
                max_length_m,
            } => {
                pos("kinematics.thigh_m", thigh_m)?;
                pos("kinematics.shank_m", shank_m)?;
                if knee_sign.abs() != 1.0 {
                    return Err(Invalid::range("kinematics.knee_sign", knee_sign, "1 or -1"));
                }
                let (lo, hi) = ((thigh_m - shank_m).abs(), thigh_m + shank_m);
                if min_length_m.is_nan() || min_length_m <= lo {
                    return Err(Invalid::range(
                        "kinematics.min_length_m",
                        min_length_m,
                        format!("> |thigh_m - shank_m| ({lo})"),
                    ));
                }
                // A straight knee is singular: the knee cannot spring the length there.
                if !(max_length_m > min_length_m && max_length_m < 0.99 * hi) {
                    return Err(Invalid::range(
                        "kinematics.max_length_m",
                        max_length_m,
                        format!(
                            "> min_length_m and < 0.99 (thigh_m + shank_m) = {:.4}",
                            0.99 * hi
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The impedance gains: none negative; stance stiffness and the damping that stops the
    /// leg and the hip positive.
    fn validate_impedance(&self) -> Result<(), Invalid> {
        let imp = &self.impedance;
        for (k, v) in [
            (
                "impedance.stance_stiffness_n_per_m",
                imp.stance_stiffness_n_per_m,
            ),
            (
                "impedance.stance_damping_n_s_per_m",
                imp.stance_damping_n_s_per_m,
            ),
            (
                "impedance.flight_stiffness_n_per_m",
                imp.flight_stiffness_n_per_m,
            ),
            (
                "impedance.flight_damping_n_s_per_m",
                imp.flight_damping_n_s_per_m,
            ),
            (
                "impedance.hip_stiffness_nm_per_rad",
                imp.hip_stiffness_nm_per_rad,
            ),
            (
                "impedance.hip_damping_nm_s_per_rad",
                imp.hip_damping_nm_s_per_rad,
            ),
            (
                "impedance.stop_damping_n_s_per_m",
                imp.stop_damping_n_s_per_m,
            ),
        ] {
            nonneg(k, v)?;
        }
        pos(
            "impedance.stance_stiffness_n_per_m",
            imp.stance_stiffness_n_per_m,
        )?;
        pos(
            "impedance.stop_damping_n_s_per_m",
            imp.stop_damping_n_s_per_m,
        )?;
        pos(
            "impedance.hip_damping_nm_s_per_rad",
            imp.hip_damping_nm_s_per_rad,
        )?;
        Ok(())
    }

    fn validate_joint(&self, which: usize) -> Result<(), Invalid> {
        let (name, j) = self.joint(which);
        let kind = self.validate_joint_fields(which)?;
        // The gains the joint must give, at the driver.
        let imp = &self.impedance;
        let (kp, kd) = if which == 0 {
            let m = self.map(0);
            (
                m.stiffness_to_driver(imp.hip_stiffness_nm_per_rad),
                m.stiffness_to_driver(imp.hip_damping_nm_s_per_rad),
            )
        } else {
            self.length_gains_needed()
        };
        let stiff_key = if which == 0 {
            "impedance.hip_stiffness_nm_per_rad"
        } else {
            "impedance.stance_stiffness_n_per_m"
        };
        match kind {
            DriverKind::Mit => validate_mit(name, j, stiff_key, kp, kd),
            DriverKind::Moteus => validate_moteus(name, j, stiff_key, kp, kd),
            DriverKind::Odrive => self.validate_odrive(which),
        }
    }

    /// A joint's driver, CAN id and mechanics (gear, direction, zero, metres per turn).
    fn validate_joint_fields(&self, which: usize) -> Result<DriverKind, Invalid> {
        let (name, j) = self.joint(which);
        let key = |k: &str| format!("{name}.{k}");
        let Some(kind) = j.driver else {
            return Err(Invalid::new(
                key("driver"),
                format!(
                    "{}: missing; one of \"moteus\", \"odrive\", \"mit\"",
                    key("driver")
                ),
            ));
        };
        let Some(id) = j.id else {
            return Err(Invalid::new(
                key("id"),
                format!("{}: missing: the joint's driver has no CAN id", key("id")),
            ));
        };
        let id_range = match kind {
            DriverKind::Moteus => 1..=127,
            DriverKind::Odrive => 0..=63,
            DriverKind::Mit => 1..=255,
        };
        if !id_range.contains(&id) {
            return Err(Invalid::range(
                &key("id"),
                id,
                format!("{}..={} for {kind:?}", id_range.start(), id_range.end()),
            ));
        }
        if !(j.gear_ratio.is_finite() && j.gear_ratio > 0.0) {
            return Err(Invalid::range(
                &key("gear_ratio"),
                j.gear_ratio,
                "a finite value > 0",
            ));
        }
        if j.direction.abs() != 1.0 {
            return Err(Invalid::range(&key("direction"), j.direction, "1 or -1"));
        }
        if !j.zero_offset.is_finite() {
            return Err(Invalid::range(
                &key("zero_offset"),
                j.zero_offset,
                "a finite value",
            ));
        }
        let prismatic_length =
            which == 1 && matches!(self.kinematics, Kinematics::Prismatic { .. });
        match (prismatic_length, j.metres_per_turn) {
            (true, Some(m)) if m.is_finite() && m > 0.0 => {}
            (true, v) => {
                return Err(Invalid::new(
                    key("metres_per_turn"),
                    format!(
                        "{} = {v:?}: a prismatic leg's length joint needs its metres per turn (> 0)",
                        key("metres_per_turn")
                    ),
                ));
            }
            (false, Some(_)) => {
                return Err(Invalid::new(
                    key("metres_per_turn"),
                    format!(
                        "{}: only a prismatic leg's length joint has one",
                        key("metres_per_turn")
                    ),
                ));
            }
            (false, None) => {}
        }
        Ok(kind)
    }

    /// An ODrive gives stiffness only with damping (cascaded loops: stiffness is pos_gain *
    /// vel_gain, with vel_gain the damping).
    fn validate_odrive(&self, which: usize) -> Result<(), Invalid> {
        let imp = &self.impedance;
        let damp_key = if which == 0 {
            "impedance.hip_damping_nm_s_per_rad"
        } else {
            "impedance.stance_damping_n_s_per_m"
        };
        let imp_d = if which == 0 {
            imp.hip_damping_nm_s_per_rad
        } else {
            imp.stance_damping_n_s_per_m
                .min(imp.flight_damping_n_s_per_m)
        };
        if imp_d <= 0.0 {
            return Err(Invalid::new(
                damp_key,
                format!(
                    "{damp_key} = {imp_d}: an ODrive gives stiffness only with damping (its position loop drives its velocity loop); > 0"
                ),
            ));
        }
        Ok(())
    }

    fn validate_ids(&self) -> Result<(), Invalid> {
        let hip = self.driver(0).bus_ids();
        let len = self.driver(1).bus_ids();
        // Two joints on one id: the same protocol with the same id (replies to a shared MIT
        // master id or a shared moteus source are told apart by the motor's id).
        if self.hip.driver == self.length.driver && self.hip.id == self.length.id {
            return Err(Invalid::new(
                "length.id",
                format!(
                    "hip.id and length.id are both {:?} on {:?}: two joints on one id",
                    self.hip.id, self.hip.driver
                ),
            ));
        }
        let shared_reply = |a: &BusId| a.what.contains("reply") || a.what.contains("master");
        for a in &hip {
            for b in &len {
                if a.id == b.id && a.extended == b.extended && !(shared_reply(a) && shared_reply(b))
                {
                    return Err(Invalid::new(
                        "length.id",
                        format!(
                            "hip's {} and length's {} share id 0x{:X}",
                            a.what, b.what, a.id
                        ),
                    ));
                }
            }
        }
        if self.motor_iface.is_some() {
            return Ok(());
        }
        // On the bus our messages use, no driver id may be one of ours.
        for (name, ids) in [("hip", &hip), ("length", &len)] {
            for b in ids.iter() {
                if let Some((kind, foot)) = self.ids.lookup(b.id, b.extended) {
                    let ours = if kind.per_foot() {
                        format!("{} of foot {foot}", kind.name())
                    } else {
                        kind.name().to_string()
                    };
                    return Err(Invalid::new(
                        format!("{name}.id"),
                        format!(
                            "{name}.id: {} (0x{:X}) is {ours}'s identifier on the shared bus; pick another id, move ours with [ids], or put the motors on their own bus (motor_iface)",
                            b.what, b.id
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// An MIT motor's ranges (its model's or given) and the gains the impedance needs within them.
fn validate_mit(
    name: &str,
    j: &JointConfig,
    stiff_key: &str,
    kp: f64,
    kd: f64,
) -> Result<(), Invalid> {
    let key = |k: &str| format!("{name}.{k}");
    let r = match (&j.mit_ranges, &j.mit_model) {
        (Some(r), _) => *r,
        (None, Some(m)) => Ranges::of_model(m).ok_or_else(|| {
            Invalid::new(
                key("mit_model"),
                format!("{} = {m:?}: not a known model; one of {:?}, or give [{}] with p_max, v_max, kp_max, kd_max, t_max", key("mit_model"), Ranges::MODELS, key("mit_ranges")),
            )
        })?,
        (None, None) => {
            return Err(Invalid::new(
                key("mit_model"),
                format!("{}: missing: an MIT motor needs its model (or {}) for its ranges", key("mit_model"), key("mit_ranges")),
            ));
        }
    };
    for (k, v) in [
        ("p_max", r.p_max),
        ("v_max", r.v_max),
        ("kp_max", r.kp_max),
        ("kd_max", r.kd_max),
        ("t_max", r.t_max),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Invalid::range(
                &key(&format!("mit_ranges.{k}")),
                v,
                "a finite value > 0",
            ));
        }
    }
    if kp > r.kp_max {
        return Err(Invalid::new(
            stiff_key,
            format!(
                "{stiff_key}: needs {kp:.3} N m/rad at {name}'s MIT motor, over its kp_max {}",
                r.kp_max
            ),
        ));
    }
    if kd > r.kd_max {
        return Err(Invalid::new(
            stiff_key,
            format!(
                "{stiff_key}: the damping needs {kd:.3} N m s/rad at {name}'s MIT motor, over its kd_max {}",
                r.kd_max
            ),
        ));
    }
    Ok(())
}

/// A moteus's configured gains (the kp and kd scales can only lower them) against the gains
/// the impedance needs, and its source id.
fn validate_moteus(
    name: &str,
    j: &JointConfig,
    stiff_key: &str,
    kp: f64,
    kd: f64,
) -> Result<(), Invalid> {
    let key = |k: &str| format!("{name}.{k}");
    let kp_full = j.moteus_kp.unwrap_or(f64::NAN);
    let kd_full = j.moteus_kd.unwrap_or(f64::NAN);
    if !(kp_full.is_finite() && kp_full > 0.0) {
        return Err(Invalid::range(
            &key("moteus_kp"),
            kp_full,
            "the controller's servo.pid_position.kp, N m/rev (> 0)",
        ));
    }
    if !(kd_full.is_finite() && kd_full > 0.0) {
        return Err(Invalid::range(
            &key("moteus_kd"),
            kd_full,
            "the controller's servo.pid_position.kd, N m s/rev (> 0)",
        ));
    }
    if j.moteus_source > 127 {
        return Err(Invalid::range(
            &key("moteus_source"),
            j.moteus_source,
            "0..=127",
        ));
    }
    if kp > kp_full / TAU {
        return Err(Invalid::new(
            stiff_key,
            format!(
                "{stiff_key}: needs {:.3} N m/rev at {name}'s moteus, over its servo.pid_position.kp {kp_full} (kp_scale can only lower it)",
                kp * TAU
            ),
        ));
    }
    if kd > kd_full / TAU {
        return Err(Invalid::new(
            stiff_key,
            format!(
                "{stiff_key}: the damping needs {:.3} N m s/rev at {name}'s moteus, over its servo.pid_position.kd {kd_full}",
                kd * TAU
            ),
        ));
    }
    Ok(())
}

/// `v` is finite and above zero, else an error naming `key`.
fn pos(key: &str, v: f64) -> Result<(), Invalid> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Invalid::range(key, v, "a finite value > 0"))
    }
}

/// `v` is finite and not below zero, else an error naming `key`.
fn nonneg(key: &str, v: f64) -> Result<(), Invalid> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Invalid::range(key, v, "a finite value >= 0"))
    }
}
