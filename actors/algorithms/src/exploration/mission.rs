//! How a robot's mission ends: it explores while a frontier is left for it, then flies
//! home along its memory's route and holds there (issue 43; the thesis' missions end on
//! a timer, §8.2.7).
//!
//! [`Mission`] is the state machine one planner keeps: [`MissionPhase::Exploring`]
//! until no frontier it has not already given up once has been left for
//! [`MissionConfig::finish_after_s`] (it is then *idle*) while every peer that reports
//! its mission is idle or done too, or until the base station commands it home, then
//! [`MissionPhase::Returning`] (the planner steers along the route distance to home,
//! [`GuidanceField::towards`](super::GuidanceField::towards)), then
//! [`MissionPhase::Home`] once the robot would come to rest within
//! [`MissionConfig::home_radius_m`] of home, where the planner commits only stopping
//! trajectories: the robot hovers, its link stays up.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use troupe_core::{ConfigError, Message, Time};

/// Where a robot is in its mission.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MissionPhase {
    /// Flying to frontiers.
    #[default]
    Exploring,
    /// Exploring has ended: flying home.
    Returning,
    /// Home: holding.
    Home,
}

impl MissionPhase {
    /// The phase's name, as reports write it.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            MissionPhase::Exploring => "exploring",
            MissionPhase::Returning => "returning",
            MissionPhase::Home => "home",
        }
    }
}

/// Why exploring ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MissionEnd {
    /// No frontier was left for the robot to explore.
    Explored,
    /// The base station commanded it home.
    Commanded,
}

/// Settings of the mission's end (`[robot.planner.mission]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MissionConfig {
    /// End exploring when nothing is left to explore, fly home and hold. `false`: the
    /// robot explores (and wanders once nothing is left) until the run ends; a
    /// command from the base still sends it home.
    pub return_home: bool,
    /// Exploring ends once no frontier has been left for this long, seconds: a
    /// frontier seen for a moment (a window rebuilt from sparse keyframe samples)
    /// does not restart it, and a short gap between openings does not end it.
    pub finish_after_s: f64,
    /// Home, world frame, metres; absent: where the robot was at its first planning
    /// round (its start).
    pub home_m: Option<[f64; 3]>,
    /// Home is reached once the robot would come to rest (braking from where it is)
    /// within this distance of it, metres.
    pub home_radius_m: f64,
    /// A return whose route home has not got 0.5 m shorter for this long retraces the
    /// robot's own trail instead (the shortest route over the memory may lead where no
    /// primitive fits); one that stalls that long again ends where the robot is (phase
    /// home, `home_gap_m` from home): a peer holding at its own home in a narrow
    /// tunnel would otherwise keep it trying for ever, seconds.
    pub stalled_after_s: f64,
    /// Homes are the team's: a returning robot flies to the deepest home no peer holds
    /// at (the one with the longest route from where its return began: its own start
    /// or a peer's, [`Mission::rank_homes`]), so the first robot back fills the place
    /// farthest in and none holds on another's way home. `false`: each robot flies to
    /// its own home (robots that start in a line in a narrow tunnel then come home in
    /// any order, and one holding at its home can block the way of one whose home lies
    /// behind it).
    pub share_homes: bool,
}

impl Default for MissionConfig {
    fn default() -> Self {
        MissionConfig {
            return_home: true,
            finish_after_s: 10.0,
            home_m: None,
            home_radius_m: 1.0,
            stalled_after_s: 15.0,
            share_homes: true,
        }
    }
}

impl MissionConfig {
    /// Checks the numbers; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::non_negative("finish_after_s", self.finish_after_s)?;
        ConfigError::positive("home_radius_m", self.home_radius_m)?;
        ConfigError::positive("stalled_after_s", self.stalled_after_s)?;
        if let Some(home) = self.home_m
            && !home.iter().all(|v| v.is_finite())
        {
            return Err(ConfigError::new(
                "home_m",
                "must be three finite numbers",
                format!("{home:?}"),
            ));
        }
        Ok(())
    }
}

/// What a robot tells its team and its reports of its mission.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MissionStatus {
    /// The phase now.
    pub phase: MissionPhase,
    /// Exploring, but no frontier has been left for the robot for
    /// [`MissionConfig::finish_after_s`]: it ends once its peers are idle or done too.
    pub idle: bool,
    /// When exploring ended, seconds of the robot's run.
    pub ended_s: Option<f64>,
    /// Why it ended.
    pub end: Option<MissionEnd>,
    /// When the robot reached home, seconds of the robot's run.
    pub home_s: Option<f64>,
    /// From the end of exploring to home, seconds.
    pub return_s: Option<f64>,
    /// Path flown from the end of exploring to home (so far, while returning), metres.
    pub return_distance_m: f64,
    /// How far from home the robot holds, metres (above `home_radius_m` when its return
    /// stalled; `None` before it holds).
    pub home_gap_m: Option<f64>,
    /// Home, world frame, metres (`None` before the first round): its own until its
    /// return chooses one of the team's ([`MissionConfig::share_homes`]), so the first
    /// status a peer gets gives the robot's own.
    pub home_m: Option<[f64; 3]>,
}

impl Message for MissionStatus {}

/// One robot's mission: its phase, its home and the times and distance of its return.
#[derive(Clone, Debug)]
pub struct Mission {
    config: MissionConfig,
    phase: MissionPhase,
    /// Where the robot flies home to: its own home, or while returning with
    /// [`MissionConfig::share_homes`] the team's home it chose.
    home_m: Option<Point3<f64>>,
    /// Its own home (the configured one, or its start).
    own_home_m: Option<Point3<f64>>,
    /// The team's homes ranked for this return, deepest first
    /// ([`Self::rank_homes`]); empty before.
    home_order: Vec<Point3<f64>>,
    /// A frontier was left at some round: exploring may end only after one was.
    had_work: bool,
    /// Since when no frontier has been left.
    idle_since: Option<Time>,
    /// No frontier has been left for `finish_after_s`.
    idle: bool,
    ended: Option<(Time, MissionEnd)>,
    home_at: Option<Time>,
    last_position_m: Option<Point3<f64>>,
    return_distance_m: f64,
    /// While returning: the shortest route home so far, metres, and when it last got
    /// `RETURN_PROGRESS_M` shorter.
    return_progress: Option<(f64, Time)>,
    /// The return stalled once on the shortest route home and now keeps to the robot's
    /// trail ([`Self::retracing`]).
    retracing: bool,
    home_gap_m: Option<f64>,
}

/// How much shorter the route home must get to count as progress, metres.
const RETURN_PROGRESS_M: f64 = 0.5;

/// Homes this close are the same place (a peer's home moved into this robot's
/// frame carries rounding), metres.
const SAME_HOME_M: f64 = 1e-3;

fn same_place(a: &Point3<f64>, b: &Point3<f64>) -> bool {
    (a - b).norm() <= SAME_HOME_M
}

impl Mission {
    /// A mission that has not begun: home is fixed at the first [`Self::update`].
    #[must_use]
    pub fn new(config: MissionConfig) -> Self {
        Mission {
            config,
            phase: MissionPhase::Exploring,
            home_m: config.home_m.map(Point3::from),
            own_home_m: config.home_m.map(Point3::from),
            home_order: Vec::new(),
            had_work: false,
            idle_since: None,
            idle: false,
            ended: None,
            home_at: None,
            last_position_m: None,
            return_distance_m: 0.0,
            return_progress: None,
            retracing: false,
            home_gap_m: None,
        }
    }

    /// The phase now.
    #[must_use]
    pub fn phase(&self) -> MissionPhase {
        self.phase
    }

    /// Where the robot flies home to (`None` before the first update when the config
    /// gives none).
    #[must_use]
    pub fn home_m(&self) -> Option<Point3<f64>> {
        self.home_m
    }

    /// Its own home: the configured one, or its start (`None` before the first update
    /// when the config gives none).
    #[must_use]
    pub fn own_home_m(&self) -> Option<Point3<f64>> {
        self.own_home_m
    }

    /// Whether the return needs the team's homes ranked: returning with
    /// [`MissionConfig::share_homes`] and not yet [`Self::rank_homes`]ed.
    #[must_use]
    pub fn wants_home_ranking(&self) -> bool {
        self.config.share_homes
            && self.phase == MissionPhase::Returning
            && self.home_order.is_empty()
    }

    /// Ranks the team's homes (`homes`: each with its route length from where the
    /// robot is as its return begins, ∞ without a known route) deepest first: by
    /// route length, longest first, ties in the order given. Homes without a route are
    /// left out; its own home is always a choice (last, when it has no route).
    pub fn rank_homes(&mut self, homes: &[(Point3<f64>, f64)]) {
        let mut ranked: Vec<(Point3<f64>, f64)> = homes
            .iter()
            .copied()
            .filter(|(_, route_m)| route_m.is_finite())
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        self.home_order = ranked.into_iter().map(|(home, _)| home).collect();
        if let Some(own) = self.own_home_m
            && !self.home_order.iter().any(|h| same_place(h, &own))
        {
            self.home_order.push(own);
        }
    }

    /// Flies to the first of the ranked homes ([`Self::rank_homes`]) that is not in
    /// `occupied` (where peers hold, home), or to its own home when all are. Returns
    /// whether where it flies to changed (its return's progress then starts afresh).
    pub fn choose_home(&mut self, occupied: &[Point3<f64>]) -> bool {
        if self.phase != MissionPhase::Returning {
            return false;
        }
        let free = self
            .home_order
            .iter()
            .find(|h| !occupied.iter().any(|o| same_place(h, o)))
            .copied()
            .or(self.own_home_m);
        if free.is_none() || free == self.home_m {
            return false;
        }
        self.home_m = free;
        self.return_progress = None;
        true
    }

    /// One planning round with the robot at `position_m` (non-finite positions are
    /// ignored), coming to rest at `rest_m` if it held from here (the end of its
    /// braking: a robot flying home at speed is home only once it would stop within
    /// [`MissionConfig::home_radius_m`], and the gap it holds at is reported from
    /// there); `work`: whether a frontier is left for it to explore; `peers_done`:
    /// whether every peer that reports its mission is idle or has ended exploring (a
    /// robot that has nothing left of its own does not end while a peer still
    /// explores: what that peer finds may be work for it, and its own memory does not
    /// know the peer's frontiers). Returns the phase for this round.
    pub fn update(
        &mut self,
        now: Time,
        position_m: &Point3<f64>,
        rest_m: &Point3<f64>,
        work: bool,
        peers_done: bool,
    ) -> MissionPhase {
        if !position_m.coords.iter().all(|v| v.is_finite()) {
            return self.phase;
        }
        let home_m = *self.home_m.get_or_insert(*position_m);
        self.own_home_m.get_or_insert(home_m);
        if self.phase == MissionPhase::Returning
            && let Some(last) = self.last_position_m
        {
            self.return_distance_m += (position_m - last).norm();
        }
        self.last_position_m = Some(*position_m);
        match self.phase {
            MissionPhase::Exploring if work => {
                self.had_work = true;
                self.idle_since = None;
                self.idle = false;
            }
            MissionPhase::Exploring if self.had_work => {
                let since = *self.idle_since.get_or_insert(now);
                self.idle = now.saturating_since(since).as_secs_f64() >= self.config.finish_after_s;
                if self.idle && peers_done && self.config.return_home {
                    self.end(now, MissionEnd::Explored);
                }
            }
            MissionPhase::Exploring | MissionPhase::Home => {}
            MissionPhase::Returning => {
                let rest_m = if rest_m.coords.iter().all(|v| v.is_finite()) {
                    rest_m
                } else {
                    position_m
                };
                let gap_m = (rest_m - home_m).norm();
                if gap_m <= self.config.home_radius_m {
                    self.hold(now, gap_m);
                }
            }
        }
        self.phase
    }

    /// While returning, the route distance home from where the robot is this round
    /// (∞ without a known route). A return whose route has not got 0.5 m shorter for
    /// [`MissionConfig::stalled_after_s`] retraces the robot's trail
    /// ([`Self::retracing`]); one that stalls again, or finds no route along the
    /// trail, ends, and the robot holds where it is.
    pub fn returning(&mut self, now: Time, route_m: f64, position_m: &Point3<f64>) {
        if self.phase != MissionPhase::Returning {
            self.return_progress = None;
            return;
        }
        if !route_m.is_finite() {
            // No known route: the robot holds and looks for one; the clock waits. Its
            // trail always led here, so a retrace without one ends.
            self.return_progress = None;
            if self.retracing {
                self.hold_short(now, position_m);
            }
            return;
        }
        let (best_m, since) = *self.return_progress.get_or_insert((route_m, now));
        if route_m <= best_m - RETURN_PROGRESS_M {
            self.return_progress = Some((route_m, now));
        } else if now.saturating_since(since).as_secs_f64() >= self.config.stalled_after_s {
            if self.retracing {
                self.hold_short(now, position_m);
            } else {
                self.retracing = true;
                self.return_progress = None;
            }
        }
    }

    /// Whether the return stalled once and now flies the robot's own trail home
    /// ([`GuidanceField::retracing`](super::GuidanceField::retracing)) instead of the
    /// shortest route over its memory.
    #[must_use]
    pub fn retracing(&self) -> bool {
        self.retracing
    }

    /// The return ends short of home: the robot holds where it is.
    fn hold_short(&mut self, now: Time, position_m: &Point3<f64>) {
        if let Some(home_m) = self.home_m {
            self.hold(now, (position_m - home_m).norm());
        }
    }

    fn hold(&mut self, now: Time, gap_m: f64) {
        self.phase = MissionPhase::Home;
        self.home_at = Some(now);
        self.home_gap_m = Some(gap_m);
    }

    /// The base station commands the robot home: exploring ends now (no change once
    /// it has ended).
    pub fn command_return(&mut self, now: Time) {
        if self.phase == MissionPhase::Exploring {
            self.end(now, MissionEnd::Commanded);
        }
    }

    fn end(&mut self, now: Time, why: MissionEnd) {
        self.phase = MissionPhase::Returning;
        self.idle = false;
        self.ended = Some((now, why));
    }

    /// The mission as reports and peers see it.
    #[must_use]
    pub fn status(&self) -> MissionStatus {
        let span_s = |from: Time, to: Time| to.saturating_since(from).as_secs_f64();
        MissionStatus {
            phase: self.phase,
            idle: self.idle,
            ended_s: self.ended.map(|(t, _)| t.as_secs_f64()),
            end: self.ended.map(|(_, why)| why),
            home_s: self.home_at.map(Time::as_secs_f64),
            return_s: self
                .ended
                .zip(self.home_at)
                .map(|((ended, _), home)| span_s(ended, home)),
            return_distance_m: self.return_distance_m,
            home_gap_m: self.home_gap_m,
            home_m: self.home_m.map(|p| [p.x, p.y, p.z]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    #[test]
    fn exploring_ends_after_the_idle_time_and_the_robot_is_home_within_the_radius() {
        let mut m = Mission::new(MissionConfig::default());
        let start = Point3::new(1.0, 2.0, 0.5);
        // No frontier before any was seen: the start, not the end.
        for s in 0..20 {
            assert_eq!(
                m.update(at(f64::from(s)), &start, &start, false, true),
                MissionPhase::Exploring
            );
        }
        let far = Point3::new(21.0, 2.0, 0.5);
        m.update(at(20.0), &far, &far, true, true);
        // 9 s without a frontier, then one for a round: still exploring.
        for s in 21..=30 {
            assert_eq!(
                m.update(at(f64::from(s)), &far, &far, false, true),
                MissionPhase::Exploring
            );
        }
        m.update(at(30.5), &far, &far, true, true);
        for s in 31..41 {
            assert_eq!(
                m.update(at(f64::from(s)), &far, &far, false, true),
                MissionPhase::Exploring
            );
        }
        // Idle from 31 s; while a peer still explores, the robot goes on.
        assert_eq!(
            m.update(at(41.0), &far, &far, false, false),
            MissionPhase::Exploring
        );
        assert!(m.status().idle);
        assert_eq!(
            m.update(at(41.0), &far, &far, false, true),
            MissionPhase::Returning
        );
        assert!(!m.status().idle);
        // Frontiers seen on the way home change nothing.
        let halfway = Point3::new(11.0, 2.0, 0.5);
        assert_eq!(
            m.update(at(50.0), &halfway, &halfway, true, true),
            MissionPhase::Returning
        );
        let near = Point3::new(1.9, 2.0, 0.5);
        // Within the radius, but flying fast enough to come to rest beyond it: not
        // home yet.
        let overshoot = Point3::new(-0.2, 2.0, 0.5);
        assert_eq!(
            m.update(at(59.0), &near, &overshoot, true, true),
            MissionPhase::Returning
        );
        let stops_at = Point3::new(0.7, 2.0, 0.5);
        assert_eq!(
            m.update(at(60.0), &near, &stops_at, true, true),
            MissionPhase::Home
        );
        assert_eq!(
            m.update(at(70.0), &far, &far, true, true),
            MissionPhase::Home
        );
        let status = m.status();
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-9);
        assert!(close(status.ended_s, 41.0));
        assert_eq!(status.end, Some(MissionEnd::Explored));
        assert!(close(status.home_s, 60.0));
        // The gap is where it comes to rest.
        assert!(close(status.home_gap_m, 0.3));
        assert!(close(status.return_s, 19.0));
        assert_eq!(status.home_m, Some([1.0, 2.0, 0.5]));
        // 10 m to halfway, 9.1 m to home; what is flown after home is not the return's.
        assert!((status.return_distance_m - 19.1).abs() < 1e-9);
    }

    #[test]
    fn a_return_flies_to_the_deepest_home_no_peer_holds_at() {
        // Robot 1 of a line in a tunnel: robot 0's start, 1.6 m farther in, is deeper.
        let own = Point3::new(2.6, 0.0, 0.0);
        let deeper = Point3::new(1.0, 0.0, 0.0);
        let unreachable = Point3::new(-9.0, 0.0, 0.0);
        let mut m = Mission::new(MissionConfig::default());
        m.update(at(0.0), &own, &own, true, true);
        let away = Point3::new(30.0, 0.0, 0.0);
        m.update(at(10.0), &away, &away, true, true);
        assert!(!m.wants_home_ranking(), "not while exploring");
        m.command_return(at(20.0));
        assert!(m.wants_home_ranking());
        m.rank_homes(&[(own, 27.4), (unreachable, f64::INFINITY), (deeper, 29.0)]);
        assert!(!m.wants_home_ranking());
        assert!(m.choose_home(&[]));
        assert_eq!(m.home_m(), Some(deeper));
        assert_eq!(m.status().home_m, Some([1.0, 0.0, 0.0]));
        // A peer holds there now: the next deepest, its own; no change after.
        assert!(m.choose_home(&[deeper]));
        assert_eq!(m.home_m(), Some(own));
        assert!(!m.choose_home(&[deeper]));
        // Every home held: its own (the home without a route was never a choice).
        assert!(!m.choose_home(&[deeper, own]));
        assert_eq!(m.home_m(), Some(own));
        let beside = Point3::new(2.9, 0.0, 0.0);
        assert_eq!(
            m.update(at(60.0), &beside, &beside, false, true),
            MissionPhase::Home
        );
        assert_eq!(m.own_home_m(), Some(own));

        // Not shared: its own home, whatever is ranked.
        let config = MissionConfig {
            share_homes: false,
            ..MissionConfig::default()
        };
        let mut m = Mission::new(config);
        m.update(at(0.0), &own, &own, true, true);
        m.command_return(at(1.0));
        assert!(!m.wants_home_ranking());
        assert!(!m.choose_home(&[]));
        assert_eq!(m.home_m(), Some(own));
    }

    #[test]
    fn a_command_sends_the_robot_home_and_return_home_off_keeps_it_exploring() {
        let config = MissionConfig {
            return_home: false,
            home_m: Some([0.0, 0.0, 1.0]),
            ..MissionConfig::default()
        };
        let mut m = Mission::new(config);
        let p = Point3::new(5.0, 0.0, 1.0);
        m.update(at(0.0), &p, &p, true, true);
        for s in 1..100 {
            assert_eq!(
                m.update(at(f64::from(s)), &p, &p, false, true),
                MissionPhase::Exploring
            );
        }
        m.command_return(at(100.0));
        assert_eq!(m.phase(), MissionPhase::Returning);
        assert_eq!(m.status().end, Some(MissionEnd::Commanded));
        m.command_return(at(101.0));
        assert!((m.status().ended_s.unwrap_or(0.0) - 100.0).abs() < 1e-9);
        let near = Point3::new(0.5, 0.0, 1.0);
        assert_eq!(
            m.update(at(110.0), &near, &near, false, true),
            MissionPhase::Home
        );
        // A non-finite pose changes nothing.
        let nan = Point3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(
            m.update(at(111.0), &nan, &nan, true, true),
            MissionPhase::Home
        );
        assert!(m.status().return_distance_m.is_finite());
    }

    #[test]
    fn bad_settings_name_their_key() {
        let bad = MissionConfig {
            home_radius_m: 0.0,
            ..MissionConfig::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("home_radius_m")
        );
        let bad = MissionConfig {
            stalled_after_s: -1.0,
            ..MissionConfig::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("stalled_after_s")
        );
        let bad = MissionConfig {
            home_m: Some([0.0, f64::NAN, 0.0]),
            ..MissionConfig::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("home_m"));
        assert!(MissionConfig::default().validate().is_ok());
    }

    #[test]
    fn a_return_that_stops_getting_nearer_retraces_the_trail_then_ends_where_the_robot_is() {
        let mut m = Mission::new(MissionConfig::default());
        let home = Point3::new(0.0, 0.0, 1.0);
        m.update(at(0.0), &home, &home, true, true);
        let blocked = Point3::new(4.0, 0.0, 1.0);
        m.command_return(at(10.0));
        // Nearer each round for 5 s, then stuck 4 m out.
        for s in 10..=15 {
            let route_m = 9.0 - f64::from(s - 10);
            m.returning(at(f64::from(s)), route_m, &blocked);
        }
        let stuck = |m: &mut Mission, from: i32, to: i32, route_m: f64| {
            for s in from..to {
                m.returning(at(f64::from(s)), route_m, &blocked);
                assert_eq!(
                    m.update(at(f64::from(s)), &blocked, &blocked, false, true),
                    MissionPhase::Returning
                );
            }
        };
        stuck(&mut m, 16, 30, 4.0);
        assert!(!m.retracing());
        // 15 s without progress: the return takes the robot's trail, whose route is
        // longer, and has 15 s again to get nearer along it.
        stuck(&mut m, 30, 46, 7.0);
        assert!(m.retracing());
        m.returning(at(46.0), 7.0, &blocked);
        assert_eq!(m.phase(), MissionPhase::Home);
        let status = m.status();
        assert!(
            (status.home_gap_m.unwrap_or(0.0) - 4.0).abs() < 1e-9,
            "{status:?}"
        );
        // Without a known route the return does not count as stalled: it waits.
        let mut m = Mission::new(MissionConfig::default());
        m.update(at(0.0), &home, &home, true, true);
        m.command_return(at(1.0));
        for s in 1..100 {
            m.returning(at(f64::from(s)), f64::INFINITY, &blocked);
        }
        assert_eq!(m.phase(), MissionPhase::Returning);
        // A retrace with no route along the trail ends at once.
        for s in 100..116 {
            m.returning(at(f64::from(s)), 4.0, &blocked);
        }
        assert!(m.retracing());
        m.returning(at(116.0), f64::INFINITY, &blocked);
        assert_eq!(m.phase(), MissionPhase::Home);
    }
}
