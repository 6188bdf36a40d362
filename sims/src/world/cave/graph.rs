//! The cave's centre-line tree, start positions and exploration routes.

use nalgebra::Point3;

/// A junction, dead end or chamber of the tunnel tree.
#[derive(Debug, Clone, PartialEq)]
pub struct CaveNode {
    /// Centre-line position in the world frame.
    pub position: Point3<f64>,
    /// Nominal free radius around the node before wall roughness: the largest radius of
    /// its tunnels and its chamber.
    pub free_radius_m: f64,
    /// The edge arriving from the parent (`None` at the entrance).
    pub parent_edge: Option<usize>,
    /// Edges leaving towards the children, in creation order.
    pub child_edges: Vec<usize>,
    /// Radius of the chamber at this node, if there is one.
    pub chamber_radius_m: Option<f64>,
}

/// A tunnel: a capsule chain along a polyline from a parent node to a child node.
#[derive(Debug, Clone, PartialEq)]
pub struct CaveEdge {
    /// Parent node.
    pub from: usize,
    /// Child node.
    pub to: usize,
    /// Tunnel radius before wall roughness.
    pub radius_m: f64,
    /// Centre-line polyline; the first point is `from`'s position, the last `to`'s.
    pub points: Vec<Point3<f64>>,
}

/// The centre-line tree of a cave, rooted at the entrance.
#[derive(Debug, Clone, PartialEq)]
pub struct CaveGraph {
    /// Nodes; index 0 is the entrance.
    pub nodes: Vec<CaveNode>,
    /// Edges (tunnels); edge 0 is the entrance tunnel.
    pub edges: Vec<CaveEdge>,
    /// Index of the entrance node.
    pub entrance: usize,
}

/// Arc length from the entrance of the first robot's start position, in metres.
pub const FIRST_START_OFFSET_M: f64 = 1.0;
/// Least straight-line distance between consecutive robots' start positions, in metres.
pub const START_SPACING_M: f64 = 1.6;

/// A point on the centre line: on segment `segment` of edge `edge`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Location {
    point: Point3<f64>,
    edge: usize,
    segment: usize,
}

/// One point of a closed tour, remembering which forward edge traversal produced it.
#[derive(Debug, Clone, Copy)]
struct TourPoint {
    point: Point3<f64>,
    /// `(edge, polyline index)` when reached walking an edge forward (away from the entrance).
    forward: Option<(usize, usize)>,
}

impl CaveGraph {
    /// Total centre-line length of all tunnels, in metres.
    #[must_use]
    pub fn total_length_m(&self) -> f64 {
        self.edges.iter().map(|e| polyline_length(&e.points)).sum()
    }

    /// Child edges of `node` in the order robot `robot_index` visits them: creation order
    /// rotated left by `robot_index`.
    fn child_order(&self, node: usize, robot_index: usize) -> Vec<usize> {
        let mut kids = self.nodes[node].child_edges.clone();
        if !kids.is_empty() {
            let k = robot_index % kids.len();
            kids.rotate_left(k);
        }
        kids
    }

    /// Closed depth-first tour from the entrance back to it.
    fn tour(&self, robot_index: usize) -> Vec<TourPoint> {
        let mut out = vec![TourPoint {
            point: self.nodes[self.entrance].position,
            forward: None,
        }];
        self.tour_from(self.entrance, robot_index, &mut out);
        out
    }

    fn tour_from(&self, node: usize, robot_index: usize, out: &mut Vec<TourPoint>) {
        for e in self.child_order(node, robot_index) {
            let pts = &self.edges[e].points;
            for (j, p) in pts.iter().enumerate().skip(1) {
                out.push(TourPoint {
                    point: *p,
                    forward: Some((e, j)),
                });
            }
            self.tour_from(self.edges[e].to, robot_index, out);
            for p in pts.iter().rev().skip(1) {
                out.push(TourPoint {
                    point: *p,
                    forward: None,
                });
            }
        }
    }

    /// The polyline from the entrance following the first child at every node, as
    /// `(edge, segment)` pairs.
    fn main_chain(&self) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut node = self.entrance;
        while let Some(&e) = self.nodes[node].child_edges.first() {
            out.extend((0..self.edges[e].points.len() - 1).map(|j| (e, j)));
            node = self.edges[e].to;
        }
        out
    }

    /// The edges off the main chain (`chain`, from [`Self::main_chain`]), breadth first
    /// from the entrance (creation order among siblings).
    fn side_edges(&self, chain: &[(usize, usize)]) -> Vec<usize> {
        let chain: std::collections::BTreeSet<usize> = chain.iter().map(|(e, _)| *e).collect();
        let mut queue = std::collections::VecDeque::from([self.entrance]);
        let mut out = Vec::new();
        while let Some(node) = queue.pop_front() {
            for &e in &self.nodes[node].child_edges {
                if !chain.contains(&e) {
                    out.push(e);
                }
                queue.push_back(self.edges[e].to);
            }
        }
        out
    }

    /// Start location of `robot_index`: see [`CaveGraph::start_position`].
    fn start_location(&self, robot_index: usize) -> Location {
        let entrance = self.nodes[self.entrance].position;
        let chain = self.main_chain();
        let Some(&(e0, _)) = chain.first() else {
            return Location {
                point: entrance,
                edge: usize::MAX,
                segment: 0,
            };
        };
        let step_m = 0.01;
        let mut placed: Vec<Point3<f64>> = Vec::new();
        let mut travelled = 0.0;
        let mut fallback = Location {
            point: entrance,
            edge: e0,
            segment: 0,
        };
        for &(e, j) in &chain {
            let (a, b) = (self.edges[e].points[j], self.edges[e].points[j + 1]);
            let len = (b - a).norm();
            let n = (len / step_m).ceil().max(1.0) as usize;
            for i in 0..n {
                let p = a + (b - a) * (i as f64 / n as f64);
                let s = travelled + len * i as f64 / n as f64;
                let here = Location {
                    point: p,
                    edge: e,
                    segment: j,
                };
                fallback = here;
                let ok = match placed.last() {
                    None => s >= FIRST_START_OFFSET_M,
                    Some(q) => (p - q).norm() >= START_SPACING_M,
                };
                if ok {
                    if placed.len() == robot_index {
                        return here;
                    }
                    placed.push(p);
                }
            }
            travelled += len;
        }
        // A team larger than the chain holds: the other tunnels, nearest the entrance
        // first, each start that far from every earlier one.
        for e in self.side_edges(&chain) {
            let points = &self.edges[e].points;
            for j in 0..points.len() - 1 {
                let (a, b) = (points[j], points[j + 1]);
                let n = ((b - a).norm() / step_m).ceil().max(1.0) as usize;
                for i in 0..n {
                    let p = a + (b - a) * (i as f64 / n as f64);
                    if placed.iter().all(|q| (p - q).norm() >= START_SPACING_M) {
                        if placed.len() == robot_index {
                            return Location {
                                point: p,
                                edge: e,
                                segment: j,
                            };
                        }
                        placed.push(p);
                    }
                }
            }
        }
        fallback
    }

    /// Start position of robot `robot_index`: on the centre line of the entrance tunnel
    /// (continuing along the first-child chain if it is too short), the first robot
    /// [`FIRST_START_OFFSET_M`] from the entrance and each next one at least
    /// [`START_SPACING_M`] further in a straight line; robots beyond what that chain holds
    /// start along the other tunnels, nearest the entrance first, at least
    /// [`START_SPACING_M`] from every earlier start (the last point of the chain only if
    /// the whole cave is full). Positions do not depend on the team size, so adding a
    /// robot moves no other.
    #[must_use]
    pub fn start_position(&self, robot_index: usize) -> Point3<f64> {
        self.start_location(robot_index).point
    }

    /// Depth-first tour of the whole tunnel tree for robot `robot_index`, along the
    /// polylines, returning along the same tunnels when backtracking. At every junction the
    /// child order is the creation order rotated left by `robot_index`, so robots take
    /// different branches first. The route starts at the robot's start position, runs the
    /// closed tour from there back to the entrance, and then walks from the entrance back
    /// to just before the start position (the only part not yet visited).
    #[must_use]
    pub fn route(&self, robot_index: usize) -> Vec<Point3<f64>> {
        let start = self.start_location(robot_index);
        let tour = self.tour(robot_index);
        // The tour point just before the forward step to polyline point `segment + 1` of
        // the start edge is point `segment` (or the parent node when `segment` is 0).
        let k = tour
            .iter()
            .position(|t| t.forward == Some((start.edge, start.segment + 1)))
            .map_or(0, |i| i.saturating_sub(1));
        let mut route = Vec::with_capacity(tour.len() + 1);
        route.push(start.point);
        route.extend(tour[k + 1..].iter().map(|t| t.point));
        route.extend(tour[1..=k].iter().map(|t| t.point));
        route.dedup_by(|a, b| (*a - *b).norm() < 1e-9);
        route
    }
}

/// Length of a polyline in metres.
#[must_use]
pub fn polyline_length(points: &[Point3<f64>]) -> f64 {
    points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}
