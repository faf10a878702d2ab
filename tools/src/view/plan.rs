//! What a view of a recording shows, decided from what the recording holds before anything is
//! drawn: the panels (one per kind of data present, none empty), each panel's legend entries
//! (one per series with data) and the step whose image is shown. Pure, so that a test checks
//! the layout without reading pixels.

use record::read::Recorded;

/// A panel against time, in the order drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PanelKind {
    /// Terrain: the truth, the bus's TerrainClass, a model's decisions.
    Terrain,
    /// The foot switch (FootContact): stance or flight.
    Contact,
    /// The gait in force (GaitStatus).
    Gait,
    /// Forward speed (the simulator's truth).
    Speed,
}

impl PanelKind {
    /// The panel's axis title.
    pub fn title(self) -> &'static str {
        match self {
            PanelKind::Terrain => "Terrain",
            PanelKind::Contact => "Contact",
            PanelKind::Gait => "Gait",
            PanelKind::Speed => "Speed (m/s)",
        }
    }
}

/// One series of a panel: what its legend says, and how many points it draws (never 0).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Series {
    /// The legend entry.
    pub label: String,
    /// Messages it draws.
    pub points: usize,
}

/// A panel and its series.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Panel {
    /// What it shows.
    pub kind: PanelKind,
    /// Its series, each with data.
    pub series: Vec<Series>,
}

/// Why the image shown was chosen.
#[derive(Clone, Debug, PartialEq)]
pub enum Shown {
    /// `--at S`: the image nearest that time.
    At(f64),
    /// The run's first step called unknown (on the bus or by the model), with its reason.
    FirstUnknown {
        /// Its step counter.
        step: u16,
        /// The reason's name, if the message carried one.
        reason: Option<String>,
    },
    /// The middle step of the run (no step was unknown).
    MiddleStep {
        /// Its step counter (none for a log without decisions: the middle stance).
        step: Option<u16>,
    },
}

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Shown::At(t) => write!(f, "the image nearest {t:.2} s (--at)"),
            Shown::FirstUnknown { step, reason } => match reason {
                Some(r) => write!(f, "step {step}, the first unknown ({r})"),
                None => write!(f, "step {step}, the first unknown"),
            },
            Shown::MiddleStep { step: Some(s) } => write!(f, "step {s}, the middle step"),
            Shown::MiddleStep { step: None } => write!(f, "the middle stance"),
        }
    }
}

/// The layout of a view.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// The time panels, top to bottom.
    pub panels: Vec<Panel>,
    /// The image shown: its index in the foot's images, and why.
    pub image: Option<(usize, Shown)>,
}

/// The foot's messages of a recording, by kind, with their times (s from the start).
pub struct FootData<'a> {
    /// Pressure images: time, and the message.
    pub images: Vec<(f64, &'a Recorded)>,
    /// TerrainClass on the bus.
    pub classes: Vec<(f64, &'a Recorded)>,
    /// TerrainClass a model decided on the way.
    pub model: Vec<(f64, &'a Recorded)>,
    /// The simulator's truth.
    pub truth: Vec<(f64, &'a Recorded)>,
    /// GaitStatus.
    pub gait: Vec<(f64, &'a Recorded)>,
    /// FootContact.
    pub contact: Vec<(f64, &'a Recorded)>,
    /// From the first message to the last, s.
    pub span: f64,
}

impl<'a> FootData<'a> {
    /// `foot`'s messages of `recording`.
    pub fn of(recording: &'a [Recorded], foot: u8) -> Self {
        let t0 = recording.iter().map(|m| m.log_time_ns).min().unwrap_or(0);
        let t = |m: &Recorded| m.log_time_ns.saturating_sub(t0) as f64 * 1e-9;
        let on = |topic: String| {
            recording
                .iter()
                .filter(|m| m.topic == topic)
                .map(|m| (t(m), m))
                .collect::<Vec<_>>()
        };
        Self {
            images: on(format!("/foot{foot}/image")),
            classes: on(format!("/foot{foot}/terrain")),
            model: on(format!("/foot{foot}/terrain/model")),
            truth: on(format!("/sim/leg{foot}")),
            gait: on("/gait".into()),
            contact: on(format!("/foot{foot}/contact")),
            span: recording.iter().map(t).fold(1e-3, f64::max),
        }
    }

    /// The truth's messages that carry `field`.
    fn truth_with(&self, field: &str) -> usize {
        self.truth
            .iter()
            .filter(|(_, m)| !m.json[field].is_null())
            .count()
    }
}

/// Legend labels.
pub const TRUE_TERRAIN: &str = "true terrain (/sim/leg)";
/// See [`TRUE_TERRAIN`].
pub const BUS_TERRAIN: &str = "TerrainClass on the bus (/terrain)";
/// See [`TRUE_TERRAIN`].
pub const MODEL_TERRAIN: &str = "the model's decision (/terrain/model)";
/// See [`TRUE_TERRAIN`].
pub const STANCE: &str = "stance (/contact)";
/// See [`TRUE_TERRAIN`].
pub const ACTIVE_GAIT: &str = "gait in force (/gait)";
/// See [`TRUE_TERRAIN`].
pub const TRUE_SPEED: &str = "true speed (/sim/leg)";

/// The layout for `d`: a panel per kind of data it holds, and the image of `at_s` or of the
/// step that says most about the run (its first unknown step, else its middle one).
pub fn plan(d: &FootData<'_>, at_s: Option<f64>) -> Layout {
    let series = |label: &str, points: usize| {
        (points > 0).then(|| Series {
            label: label.to_string(),
            points,
        })
    };
    let candidates = [
        (
            PanelKind::Terrain,
            vec![
                series(TRUE_TERRAIN, d.truth_with("Terrain")),
                series(BUS_TERRAIN, d.classes.len()),
                series(MODEL_TERRAIN, d.model.len()),
            ],
        ),
        (PanelKind::Contact, vec![series(STANCE, d.contact.len())]),
        (PanelKind::Gait, vec![series(ACTIVE_GAIT, d.gait.len())]),
        (
            PanelKind::Speed,
            vec![series(TRUE_SPEED, d.truth_with("SpeedMps"))],
        ),
    ];
    let panels = candidates
        .into_iter()
        .filter_map(|(kind, s)| {
            let series: Vec<Series> = s.into_iter().flatten().collect();
            (!series.is_empty()).then_some(Panel { kind, series })
        })
        .collect();
    Layout {
        panels,
        image: shown_image(d, at_s),
    }
}

/// The image shown and why: nearest `at_s`; else the most loaded image of the first unknown
/// step's stance (the model's decisions first: they are what the view is usually made to
/// judge), else of the middle step, else of the middle stance of the foot switch.
fn shown_image(d: &FootData<'_>, at_s: Option<f64>) -> Option<(usize, Shown)> {
    if d.images.is_empty() {
        return None;
    }
    if let Some(a) = at_s {
        let i = (0..d.images.len()).min_by(|&x, &y| {
            (d.images[x].0 - a)
                .abs()
                .total_cmp(&(d.images[y].0 - a).abs())
        })?;
        return Some((i, Shown::At(a)));
    }
    let decisions = if d.model.is_empty() {
        &d.classes
    } else {
        &d.model
    };
    let step = |m: &Recorded| m.json["Step"].as_u64().map(|s| s as u16);
    let unknown = decisions.iter().find(|(_, m)| {
        m.json["TerrainId"].as_u64() == Some(u64::from(protocol::messages::TERRAIN_UNKNOWN))
    });
    let (decided_at, why) = match unknown {
        Some((t, m)) => (
            *t,
            Shown::FirstUnknown {
                step: step(m).unwrap_or(0),
                reason: reason_of(m),
            },
        ),
        None if !decisions.is_empty() => {
            let (t, m) = decisions[decisions.len() / 2];
            (t, Shown::MiddleStep { step: step(m) })
        }
        None => {
            // No decision in the log: the middle stance by the foot switch.
            let stances: Vec<f64> = d
                .contact
                .windows(2)
                .filter(|w| !in_stance(w[0].1) && in_stance(w[1].1))
                .map(|w| w[1].0)
                .collect();
            let td = stances.get(stances.len() / 2).copied();
            let end = td.map_or(d.span, |t| t + 0.3);
            (end, Shown::MiddleStep { step: None })
        }
    };
    // The stance's images end at its decision (or 300 ms into it); the most loaded of the 200
    // ms before is the one the node took, or near it.
    let load = |m: &Recorded| {
        record::read::mono8_image(&m.json)
            .map_or(0, |(_, _, px)| px.iter().map(|&p| p as u64).sum())
    };
    let i = (0..d.images.len())
        .filter(|&i| d.images[i].0 <= decided_at && d.images[i].0 >= decided_at - 0.2)
        .max_by_key(|&i| load(d.images[i].1))
        .unwrap_or(d.images.len() - 1);
    Some((i, why))
}

/// Why a recorded TerrainClass is unknown: its `UnknownReason`'s label, else its flags'
/// (energy, no sample, no contact).
fn reason_of(m: &Recorded) -> Option<String> {
    let j = &m.json;
    if let Some(r) = j["UnknownReasonName"]
        .as_str()
        .filter(|r| !r.is_empty() && *r != "none")
    {
        return Some(r.to_string());
    }
    [
        ("FlagEnergy", "energy"),
        ("FlagNoSample", "no_sample"),
        ("FlagNoContact", "no_contact"),
    ]
    .into_iter()
    .find(|(flag, _)| j[*flag].as_u64() == Some(1))
    .map(|(_, name)| name.to_string())
}

/// A FootContact message that says stance.
pub fn in_stance(m: &Recorded) -> bool {
    m.json["Contact"].as_u64() == Some(1) || m.json["Contact"].as_bool() == Some(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(topic: &str, t_ms: u64, json: serde_json::Value) -> Recorded {
        Recorded {
            topic: topic.into(),
            log_time_ns: t_ms * 1_000_000,
            json,
        }
    }

    fn image(t_ms: u64, v: u8) -> Recorded {
        use base64::Engine;
        let px = vec![v; 4];
        let mut data = String::new();
        base64::engine::general_purpose::STANDARD.encode_string(&px, &mut data);
        msg(
            "/foot0/image",
            t_ms,
            serde_json::json!({"encoding": "mono8", "width": 2, "height": 2, "data": data}),
        )
    }

    fn terrain(topic: &str, t_ms: u64, step: u16, id: u8) -> Recorded {
        let reason = if id == 255 { "novelty" } else { "none" };
        msg(
            topic,
            t_ms,
            serde_json::json!({"Step": step, "TerrainId": id, "Terrain": "x", "UnknownReasonName": reason}),
        )
    }

    /// A foot's traffic: a flight, a stance with its images, for `steps` steps of 400 ms.
    fn foot_only(steps: u16) -> Vec<Recorded> {
        let mut v = Vec::new();
        for s in 0..steps as u64 {
            let t = s * 400;
            v.push(msg("/foot0/contact", t, serde_json::json!({"Contact": 0})));
            v.push(msg(
                "/foot0/contact",
                t + 100,
                serde_json::json!({"Contact": 1}),
            ));
            for k in 0..5 {
                v.push(image(t + 110 + k * 10, (s as u8 + 1) * 10 + k as u8));
            }
        }
        v
    }

    #[test]
    fn a_foot_only_log_gets_contact_and_image_and_the_models_terrain_and_nothing_empty() {
        let rec = foot_only(5);
        let d = FootData::of(&rec, 0);
        let l = plan(&d, None);
        let kinds: Vec<PanelKind> = l.panels.iter().map(|p| p.kind).collect();
        assert_eq!(
            kinds,
            vec![PanelKind::Contact],
            "no decisions: contact alone"
        );
        assert_eq!(
            l.image.as_ref().unwrap().1,
            Shown::MiddleStep { step: None }
        );
        // With a model's decisions (`presrs mcap --model`): its terrain too, and no series
        // without data (no bus TerrainClass, no truth) in the legend.
        let mut rec = foot_only(5);
        for s in 0..5u16 {
            let id = if s == 3 { 255 } else { 0 };
            rec.push(terrain(
                "/foot0/terrain/model",
                s as u64 * 400 + 160,
                s + 1,
                id,
            ));
        }
        let d = FootData::of(&rec, 0);
        let l = plan(&d, None);
        let kinds: Vec<PanelKind> = l.panels.iter().map(|p| p.kind).collect();
        assert_eq!(kinds, vec![PanelKind::Terrain, PanelKind::Contact]);
        let labels: Vec<&str> = l.panels[0]
            .series
            .iter()
            .map(|s| s.label.as_str())
            .collect();
        assert_eq!(labels, vec![MODEL_TERRAIN]);
        assert!(
            l.panels
                .iter()
                .all(|p| p.series.iter().all(|s| s.points > 0))
        );
        // The first unknown step's image, its most loaded one before the decision.
        let (i, why) = l.image.unwrap();
        assert_eq!(
            why,
            Shown::FirstUnknown {
                step: 4,
                reason: Some("novelty".into())
            }
        );
        assert_eq!(
            d.images[i].0, 1.35,
            "the last (most loaded) image of step 4's stance"
        );
        assert_eq!(why.to_string(), "step 4, the first unknown (novelty)");
    }

    #[test]
    fn a_demo_recording_gets_every_panel_and_at_picks_the_nearest_image() {
        let mut rec = foot_only(3);
        for s in 0..3u16 {
            let t = s as u64 * 400;
            rec.push(terrain("/foot0/terrain", t + 160, s + 1, 0));
            rec.push(msg("/gait", t + 170, serde_json::json!({"ActiveGait": 2})));
            rec.push(msg(
                "/sim/leg0",
                t + 5,
                serde_json::json!({"Terrain": "wood", "SpeedMps": 0.5}),
            ));
        }
        let d = FootData::of(&rec, 0);
        let l = plan(&d, None);
        let kinds: Vec<PanelKind> = l.panels.iter().map(|p| p.kind).collect();
        assert_eq!(
            kinds,
            vec![
                PanelKind::Terrain,
                PanelKind::Contact,
                PanelKind::Gait,
                PanelKind::Speed
            ]
        );
        assert_eq!(
            l.panels[0].series.len(),
            2,
            "truth and the bus's TerrainClass"
        );
        assert_eq!(
            l.image.as_ref().unwrap().1,
            Shown::MiddleStep { step: Some(2) }
        );
        let l = plan(&d, Some(0.131));
        let (i, why) = l.image.unwrap();
        assert_eq!((d.images[i].0, why), (0.13, Shown::At(0.131)));
        // A recording without images shows none.
        let none: Vec<Recorded> = rec
            .into_iter()
            .filter(|m| m.topic != "/foot0/image")
            .collect();
        assert!(plan(&FootData::of(&none, 0), None).image.is_none());
    }
}
