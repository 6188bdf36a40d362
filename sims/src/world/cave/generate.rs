//! Growing the tunnel tree and placing chambers, deterministically from a seeded RNG.

use std::f64::consts::PI;

use nalgebra::{Point3, Vector3};
use rand::{Rng, seq::SliceRandom};
use rand_chacha::ChaCha8Rng;

use super::graph::{CaveEdge, CaveGraph, CaveNode};
use super::params::CaveParams;

/// Tries per wanted tunnel before growth gives up.
const TRIES_PER_TUNNEL: usize = 60;

/// Grow the centre-line tree and pick chamber nodes.
pub(super) fn grow(params: &CaveParams, rng: &mut ChaCha8Rng) -> CaveGraph {
    let mut g = CaveGraph {
        nodes: vec![CaveNode {
            position: Point3::origin(),
            free_radius_m: 0.0,
            parent_edge: None,
            child_edges: Vec::new(),
            chamber_radius_m: None,
        }],
        edges: Vec::new(),
        entrance: 0,
    };
    let radius = |rng: &mut ChaCha8Rng| {
        rng.random_range(params.tunnel_radius_min_m..=params.tunnel_radius_max_m)
    };
    let trunk_grade = rng.random_range(-0.5..=0.5) * params.max_grade;
    let r = radius(rng);
    let trunk = polyline(
        params,
        rng,
        Point3::origin(),
        0.0,
        params.entrance_tunnel_length_m,
        trunk_grade,
    );
    add_edge(&mut g, 0, trunk, r);

    let mut tries = 0;
    while g.edges.len() < params.tunnel_count && tries < TRIES_PER_TUNNEL * params.tunnel_count {
        tries += 1;
        let candidates: Vec<usize> = (1..g.nodes.len())
            .filter(|&n| g.nodes[n].child_edges.len() < 2)
            .collect();
        let Some(&node) = candidates.get(rng.random_range(0..candidates.len().max(1))) else {
            break;
        };
        let arrival = arrival_yaw(&g, node);
        let yaw = match g.nodes[node].child_edges.first() {
            None => arrival + rng.random_range(-35f64..=35.0).to_radians(),
            Some(&sibling) => {
                let s = &g.edges[sibling].points;
                let d = s[1] - s[0];
                let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                let y = d.y.atan2(d.x) + sign * rng.random_range(55f64..=95.0).to_radians();
                // Never turn back more than 130 degrees from the arrival direction.
                if wrap_angle(y - arrival).abs() > 130f64.to_radians() {
                    continue;
                }
                y
            }
        };
        let length = rng.random_range(params.tunnel_length_min_m..=params.tunnel_length_max_m);
        let grade = rng.random_range(-1.0..=1.0) * params.max_grade;
        let r = radius(rng);
        let pts = polyline(params, rng, g.nodes[node].position, yaw, length, grade);
        if fits(&g, params, node, &pts, r) {
            add_edge(&mut g, node, pts, r);
        }
    }
    place_chambers(&mut g, params, rng);
    for n in 0..g.nodes.len() {
        let node = &g.nodes[n];
        let tunnels = node
            .parent_edge
            .iter()
            .chain(node.child_edges.iter())
            .map(|&e| g.edges[e].radius_m)
            .fold(0.0, f64::max);
        g.nodes[n].free_radius_m = tunnels.max(node.chamber_radius_m.unwrap_or(0.0));
    }
    g
}

/// Heading of the last segment arriving at `node`.
fn arrival_yaw(g: &CaveGraph, node: usize) -> f64 {
    g.nodes[node].parent_edge.map_or(0.0, |e| {
        let p = &g.edges[e].points;
        let d = p[p.len() - 1] - p[p.len() - 2];
        d.y.atan2(d.x)
    })
}

fn wrap_angle(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// A wiggly polyline from `start` with initial heading `yaw` (radians).
fn polyline(
    params: &CaveParams,
    rng: &mut ChaCha8Rng,
    start: Point3<f64>,
    mut yaw: f64,
    length_m: f64,
    grade: f64,
) -> Vec<Point3<f64>> {
    let n = (length_m / params.segment_length_m).ceil().max(1.0) as usize;
    let step = length_m / n as f64;
    let wiggle = params.wiggle_deg.to_radians();
    let mut pts = vec![start];
    let mut p = start;
    for i in 0..n {
        if i > 0 && wiggle > 0.0 {
            yaw += rng.random_range(-wiggle..=wiggle);
        }
        let g = if params.max_grade > 0.0 {
            (grade + rng.random_range(-0.3..=0.3) * params.max_grade)
                .clamp(-params.max_grade, params.max_grade)
        } else {
            0.0
        };
        p += Vector3::new(yaw.cos(), yaw.sin(), g) * step;
        pts.push(p);
    }
    pts
}

fn add_edge(g: &mut CaveGraph, from: usize, points: Vec<Point3<f64>>, radius_m: f64) {
    let to = g.nodes.len();
    let e = g.edges.len();
    let position = points[points.len() - 1];
    g.nodes.push(CaveNode {
        position,
        free_radius_m: 0.0,
        parent_edge: Some(e),
        child_edges: Vec::new(),
        chamber_radius_m: None,
    });
    g.nodes[from].child_edges.push(e);
    g.edges.push(CaveEdge {
        from,
        to,
        radius_m,
        points,
    });
}

/// Distance from `p` to a polyline.
pub(super) fn polyline_distance_m(p: &Point3<f64>, pts: &[Point3<f64>]) -> f64 {
    pts.windows(2)
        .map(|w| {
            let ab = w[1] - w[0];
            let t = ((p - w[0]).dot(&ab) / ab.norm_squared().max(1e-12)).clamp(0.0, 1.0);
            (p - (w[0] + ab * t)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Whether a new tunnel from `node` along `pts` keeps its distance from the others and
/// stays within reach of the entrance.
fn fits(g: &CaveGraph, params: &CaveParams, node: usize, pts: &[Point3<f64>], r: f64) -> bool {
    if pts
        .iter()
        .any(|p| p.xy().coords.norm() > params.max_reach_m)
    {
        return false;
    }
    let mut arc = 0.0;
    for (i, p) in pts.iter().enumerate() {
        if i > 0 {
            arc += (pts[i] - pts[i - 1]).norm();
        }
        for edge in &g.edges {
            let need = r + edge.radius_m + params.min_wall_gap_m;
            let incident = edge.to == node || edge.from == node;
            // Tunnels meeting at `node` merge near it; demand the gap only further out.
            if incident && arc < need / 35f64.to_radians().sin() {
                continue;
            }
            if polyline_distance_m(p, &edge.points) < need {
                return false;
            }
        }
    }
    true
}

/// Put chambers on leaves first, then junctions, where they keep clear of other tunnels.
fn place_chambers(g: &mut CaveGraph, params: &CaveParams, rng: &mut ChaCha8Rng) {
    let mut leaves: Vec<usize> = (1..g.nodes.len())
        .filter(|&n| g.nodes[n].child_edges.is_empty())
        .collect();
    let mut inner: Vec<usize> = (1..g.nodes.len())
        .filter(|&n| !g.nodes[n].child_edges.is_empty())
        .collect();
    leaves.shuffle(rng);
    inner.shuffle(rng);
    let mut placed = 0;
    for n in leaves.into_iter().chain(inner) {
        if placed >= params.chamber_count {
            break;
        }
        let wanted = rng.random_range(params.chamber_radius_min_m..=params.chamber_radius_max_m);
        let c = g.nodes[n].position;
        let fits_with = |radius: f64| {
            let clear_of_tunnels = g.edges.iter().all(|e| {
                e.from == n
                    || e.to == n
                    || polyline_distance_m(&c, &e.points)
                        >= radius + e.radius_m + params.min_wall_gap_m
            });
            let clear_of_chambers = g.nodes.iter().all(|m| {
                m.chamber_radius_m
                    .is_none_or(|rm| (m.position - c).norm() >= radius + rm + params.min_wall_gap_m)
            });
            let clear_of_entrance = (g.nodes[g.entrance].position - c).norm()
                >= radius + params.tunnel_radius_max_m + params.min_wall_gap_m;
            clear_of_tunnels && clear_of_chambers && clear_of_entrance
        };
        let radius = [wanted, params.chamber_radius_min_m]
            .into_iter()
            .find(|&r| fits_with(r));
        if let Some(radius) = radius {
            g.nodes[n].chamber_radius_m = Some(radius);
            placed += 1;
        }
    }
}
