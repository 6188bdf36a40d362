//! Scripted tunnel worlds for exploration tests: a T-junction and a dead end.
//!
//! Both are caves ([`CaveWorld::from_graph`]) along a fixed, straight, level centre-line
//! tree instead of a grown one, with the cave's rough, textured walls (so the camera,
//! the mapper and the GPU renderer treat them like any cave). Robots start on the
//! entrance tunnel facing into it, 1 m from the closed entrance and 1.6 m apart
//! ([`super::cave::FIRST_START_OFFSET_M`], [`super::cave::START_SPACING_M`]). Only the
//! wall roughness depends on the world seed.
//!
//! - **T-junction** (`kind = "t_junction"`): a stem along +x from the entrance to a
//!   junction `junction_distance_m` ahead, where two arms of `branch_length_m` leave to
//!   +y and −y. A fork: two robots should take different arms.
//! - **Dead end** (`kind = "dead_end"`): a tunnel along +x that ends blind
//!   `dead_end_length_m` ahead, and a side tunnel of `side_length_m` leaving to +y at
//!   the entrance, beside and behind the start positions, out of the cameras' view at
//!   the start. With the default 24 m, the side opening lies outside a 20 m grid window
//!   centred at the dead end: a robot there has to remember it to go back.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::cave::{CaveEdge, CaveGraph, CaveNode, CaveParams, CaveWorld, ROUTE_CLEARANCE_M};

/// Spacing of the centre-line points, metres.
const POINT_SPACING_M: f64 = 2.0;

/// Shape of the scripted tunnel worlds (`[world.tunnel]`); lengths in metres along the
/// centre lines.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TunnelParams {
    /// Tunnel radius before wall roughness.
    pub radius_m: f64,
    /// T-junction: from the entrance to the junction.
    pub junction_distance_m: f64,
    /// T-junction: length of each arm.
    pub branch_length_m: f64,
    /// Dead end: from the entrance to the blind end.
    pub dead_end_length_m: f64,
    /// Dead end: length of the side tunnel at the entrance.
    pub side_length_m: f64,
    /// Amplitude of the wall roughness.
    pub wall_noise_amplitude_m: f64,
    /// Spatial wavelength of the wall roughness.
    pub wall_noise_wavelength_m: f64,
}

impl Default for TunnelParams {
    fn default() -> Self {
        TunnelParams {
            radius_m: 1.8,
            junction_distance_m: 10.0,
            branch_length_m: 10.0,
            dead_end_length_m: 24.0,
            side_length_m: 12.0,
            wall_noise_amplitude_m: 0.15,
            wall_noise_wavelength_m: 1.6,
        }
    }
}

impl TunnelParams {
    /// Checks every field; the error names the field, the rule and the value.
    ///
    /// # Errors
    ///
    /// A length that is not finite and positive, a negative roughness, or a radius
    /// that leaves less than the route clearance inside the rough walls.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, v) in [
            ("radius_m", self.radius_m),
            ("junction_distance_m", self.junction_distance_m),
            ("branch_length_m", self.branch_length_m),
            ("dead_end_length_m", self.dead_end_length_m),
            ("side_length_m", self.side_length_m),
            ("wall_noise_wavelength_m", self.wall_noise_wavelength_m),
        ] {
            ConfigError::positive(key, v)?;
        }
        let a = self.wall_noise_amplitude_m;
        ConfigError::non_negative("wall_noise_amplitude_m", a)?;
        let clearance = self.radius_m - a;
        if clearance < ROUTE_CLEARANCE_M + 0.1 {
            return Err(ConfigError::new(
                "radius_m",
                format!(
                    "minus `wall_noise_amplitude_m` must be at least {} m",
                    ROUTE_CLEARANCE_M + 0.1
                ),
                clearance,
            ));
        }
        Ok(())
    }

    /// The cave parameters that [`CaveWorld::from_graph`] reads: radius and roughness.
    fn cave_params(&self) -> CaveParams {
        CaveParams {
            tunnel_radius_min_m: self.radius_m,
            tunnel_radius_max_m: self.radius_m,
            wall_noise_amplitude_m: self.wall_noise_amplitude_m,
            wall_noise_wavelength_m: self.wall_noise_wavelength_m,
            ..CaveParams::default()
        }
    }
}

/// The T-junction world (see the module documentation); `params` should have passed
/// [`TunnelParams::validate`].
#[must_use]
pub fn t_junction(params: &TunnelParams, seed: u64) -> CaveWorld {
    let mut g = Tree::new(params.radius_m);
    let junction = g.add(0, Vector3::x(), params.junction_distance_m);
    g.add(junction, Vector3::y(), params.branch_length_m);
    g.add(junction, -Vector3::y(), params.branch_length_m);
    CaveWorld::from_graph(&params.cave_params(), g.graph, seed)
}

/// The dead-end world (see the module documentation); `params` should have passed
/// [`TunnelParams::validate`].
#[must_use]
pub fn dead_end(params: &TunnelParams, seed: u64) -> CaveWorld {
    let mut g = Tree::new(params.radius_m);
    // The first child of the entrance is the tunnel the robots start in.
    g.add(0, Vector3::x(), params.dead_end_length_m);
    g.add(0, Vector3::y(), params.side_length_m);
    CaveWorld::from_graph(&params.cave_params(), g.graph, seed)
}

/// A centre-line tree of straight, level tunnels of one radius, grown from the entrance
/// at the origin.
struct Tree {
    graph: CaveGraph,
    radius_m: f64,
}

impl Tree {
    fn new(radius_m: f64) -> Tree {
        Tree {
            graph: CaveGraph {
                nodes: vec![CaveNode {
                    position: Point3::origin(),
                    free_radius_m: radius_m,
                    parent_edge: None,
                    child_edges: Vec::new(),
                    chamber_radius_m: None,
                }],
                edges: Vec::new(),
                entrance: 0,
            },
            radius_m,
        }
    }

    /// Adds a straight tunnel of `length_m` from node `from` along the unit vector
    /// `direction`, and returns its end node.
    fn add(&mut self, from: usize, direction: Vector3<f64>, length_m: f64) -> usize {
        let start = self.graph.nodes[from].position;
        let steps = (length_m / POINT_SPACING_M).ceil().max(1.0) as usize;
        let points: Vec<Point3<f64>> = (0..=steps)
            .map(|k| start + direction * (length_m * k as f64 / steps as f64))
            .collect();
        let (to, edge) = (self.graph.nodes.len(), self.graph.edges.len());
        self.graph.nodes.push(CaveNode {
            position: points[steps],
            free_radius_m: self.radius_m,
            parent_edge: Some(edge),
            child_edges: Vec::new(),
            chamber_radius_m: None,
        });
        self.graph.nodes[from].child_edges.push(edge);
        self.graph.edges.push(CaveEdge {
            from,
            to,
            radius_m: self.radius_m,
            points,
        });
        to
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use crate::world::{Site, World, WorldKind};
    use troupe_core::ErrorChain;

    #[test]
    fn the_t_junction_is_open_along_its_arms_and_closed_elsewhere() {
        let p = TunnelParams::default();
        let w = t_junction(&p, 3);
        let free = |x: f64, y: f64| w.sdf_m(&Point3::new(x, y, 0.0)) > 0.0;
        for x in [0.0, 5.0, 10.0] {
            assert!(free(x, 0.0), "stem at x = {x}");
        }
        for y in [-10.0, -5.0, 5.0, 10.0] {
            assert!(free(10.0, y), "arm at y = {y}");
        }
        assert!(!free(15.0, 0.0), "nothing beyond the junction");
        assert!(!free(5.0, 5.0), "rock between stem and arm");
        assert!(!free(-3.0, 0.0), "the entrance is closed");
        let start = w.start_position(0, 2);
        assert!(
            (start - Point3::new(1.0, 0.0, 0.0)).norm() < 0.02,
            "{start}"
        );
        assert!(w.start_position(1, 2).x > start.x + 1.5);
        assert_eq!(w.route_length_m(), 30.0);
        // Robots tour the arms in different orders.
        let first_arm = |route: Vec<Point3<f64>>| {
            route
                .iter()
                .find(|q| q.y.abs() > 2.0)
                .map(|q| q.y.signum())
                .expect("the route enters an arm")
        };
        assert_ne!(first_arm(w.route(0, 2)), first_arm(w.route(1, 2)));
    }

    #[test]
    fn the_dead_end_has_its_side_opening_behind_the_start() {
        let p = TunnelParams::default();
        let w = dead_end(&p, 3);
        let free = |x: f64, y: f64| w.sdf_m(&Point3::new(x, y, 0.0)) > 0.0;
        assert!(free(23.0, 0.0));
        assert!(!free(27.0, 0.0), "the tunnel ends blind");
        assert!(free(0.0, 8.0), "side tunnel");
        assert!(!free(4.0, 4.0), "no other opening");
        for i in 0..2 {
            let s = w.start_position(i, 2);
            assert!(s.x >= 1.0 && s.y.abs() < 1e-9, "robot {i} at {s}");
        }
        let b = w.bounds();
        assert!(b.max.x < 26.5 && b.max.y < 14.5 && b.min.x > -2.5, "{b:?}");
    }

    #[test]
    fn the_same_seed_gives_the_same_walls_and_bad_params_are_named() {
        let p = TunnelParams::default();
        let q = Point3::new(5.0, 1.7, 0.3);
        assert_eq!(t_junction(&p, 5).sdf_m(&q), t_junction(&p, 5).sdf_m(&q));
        assert_ne!(t_junction(&p, 5).sdf_m(&q), t_junction(&p, 6).sdf_m(&q));
        assert_eq!(p.validate(), Ok(()));
        let cases = [
            (
                TunnelParams {
                    radius_m: 1.0,
                    ..p.clone()
                },
                "radius_m",
            ),
            (
                TunnelParams {
                    branch_length_m: f64::NAN,
                    ..p.clone()
                },
                "branch_length_m",
            ),
            (
                TunnelParams {
                    wall_noise_amplitude_m: -0.1,
                    ..p.clone()
                },
                "wall_noise_amplitude_m",
            ),
        ];
        for (bad, needle) in cases {
            assert_eq!(bad.validate().expect_err(needle).key, needle);
        }
    }

    #[test]
    fn scenarios_name_the_tunnel_kinds_and_their_bad_keys() {
        let parse = |text: &str| Scenario::from_toml(text, std::path::Path::new("s.toml"));
        let s = parse("[world]\nkind = \"dead_end\"\n[world.tunnel]\nside_length_m = 6.0\n")
            .expect("valid");
        assert_eq!(s.world.kind, WorldKind::DeadEnd);
        assert_eq!(s.world.tunnel.side_length_m, 6.0);
        let bad = |text: &str| ErrorChain(&parse(text).expect_err(text)).to_string();
        let message = bad("[world]\nkind = \"t_junction\"\n[world.tunnel]\nradius_m = -1.0\n");
        assert!(
            message.contains("world.tunnel") && message.contains("radius_m"),
            "{message}"
        );
        let message = bad("[world]\nkind = \"t_junction\"\n[world.tunnel]\nradius = 2.0\n");
        assert!(message.contains("radius"), "{message}");
    }
}
