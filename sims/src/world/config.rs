//! The `[world]` table of a scenario: which world, from which seed, with which shape.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::artifacts::{ArtifactParams, WithArtifacts, place};
use super::mesh::MeshError;
use super::{
    CaveParams, CaveWorld, DoorParams, MeshParams, MeshWorld, OpenField, OpenFieldParams,
    OpeningScene, Room, RoomParams, Site, TunnelParams, Warehouse, WarehouseParams, WindowParams,
    tunnels,
};

/// A built world and where its artifacts are ([`WorldConfig::build_with_artifacts`]).
pub type SiteWithArtifacts = (Arc<dyn Site>, Vec<nalgebra::Point3<f64>>);

/// The kinds of world `troupe run` can build.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorldKind {
    /// Procedural cave tunnels and chambers (`[world.cave]`).
    Cave,
    /// Warehouse with rows of shelves (`[world.warehouse]`, thesis §4.2.2).
    Warehouse,
    /// A wall with a window 10 m ahead (`[world.window]`, thesis §5.2.1).
    Window,
    /// A building with a door 12 m ahead (`[world.door]`, thesis §5.2).
    Door,
    /// A triangle mesh from a PLY or OBJ file (`[world.mesh]`).
    Mesh,
    /// Flat ground with a few boxes; routes cross at the centre (`[world.open_field]`).
    OpenField,
    /// A tunnel forking into two arms (`[world.tunnel]`, [`tunnels::t_junction`]).
    TJunction,
    /// A blind tunnel with a side tunnel behind the start (`[world.tunnel]`,
    /// [`tunnels::dead_end`]).
    DeadEnd,
    /// A rectangular room with solid boxes (pillars) in it (`[world.room]`), the room
    /// the hardware robot's benchmark flies (`scripts/hardware_bench/`).
    Room,
}

/// The world to explore.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldConfig {
    /// Which world.
    pub kind: WorldKind,
    /// Seed of the world generator (separate from the run seed, so that one world can
    /// be explored under many run seeds).
    pub seed: u64,
    /// Cave generator parameters.
    pub cave: CaveParams,
    /// Warehouse parameters.
    pub warehouse: WarehouseParams,
    /// Window scene parameters.
    pub window: WindowParams,
    /// Door scene parameters.
    pub door: DoorParams,
    /// Mesh world parameters.
    pub mesh: MeshParams,
    /// Open field parameters.
    pub open_field: OpenFieldParams,
    /// Scripted tunnel parameters (not written when default, so that records of
    /// earlier runs still compare equal).
    #[serde(skip_serializing_if = "is_default_tunnel")]
    pub tunnel: TunnelParams,
    /// Room parameters (not written when default, so that records of earlier runs
    /// still compare equal).
    #[serde(skip_serializing_if = "is_default_room")]
    pub room: RoomParams,
    /// Artifacts placed in the world by its seed (`count = 0`: none).
    pub artifacts: ArtifactParams,
}

fn is_default_tunnel(p: &TunnelParams) -> bool {
    *p == TunnelParams::default()
}

fn is_default_room(p: &RoomParams) -> bool {
    *p == RoomParams::default()
}

impl Default for WorldConfig {
    fn default() -> Self {
        WorldConfig {
            kind: WorldKind::Cave,
            seed: 7,
            cave: CaveParams::default(),
            warehouse: WarehouseParams::default(),
            window: WindowParams::default(),
            door: DoorParams::default(),
            mesh: MeshParams::default(),
            open_field: OpenFieldParams::default(),
            tunnel: TunnelParams::default(),
            room: RoomParams::default(),
            artifacts: ArtifactParams::default(),
        }
    }
}

impl WorldConfig {
    /// Checks the parameters of the selected world.
    ///
    /// # Errors
    ///
    /// The offending key relative to `[world]` (`cave.tunnel_count`), its rule and its
    /// value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.artifacts
            .validate()
            .map_err(|e| e.within("artifacts"))?;
        let (table, checked) = match self.kind {
            WorldKind::Cave => ("cave", self.cave.validate()),
            WorldKind::Warehouse => ("warehouse", self.warehouse.validate()),
            WorldKind::Window => ("window", self.window.validate()),
            WorldKind::Door => ("door", self.door.validate()),
            WorldKind::Mesh => ("mesh", self.mesh.validate()),
            WorldKind::OpenField => ("open_field", self.open_field.validate()),
            WorldKind::TJunction | WorldKind::DeadEnd => ("tunnel", self.tunnel.validate()),
            WorldKind::Room => ("room", self.room.validate()),
        };
        checked.map_err(|e| e.within(table))
    }

    /// Builds the selected world (validate first).
    ///
    /// # Errors
    ///
    /// A mesh file that cannot be read.
    pub fn build(&self) -> Result<Arc<dyn Site>, MeshError> {
        Ok(self.build_with_artifacts()?.0)
    }

    /// Like [`build`](Self::build), and where the artifacts are (the ground truth
    /// an artifact score compares with; empty with `artifacts.count = 0`).
    ///
    /// # Errors
    ///
    /// A mesh file that cannot be read.
    pub fn build_with_artifacts(&self) -> Result<SiteWithArtifacts, MeshError> {
        let site = self.build_site()?;
        if self.artifacts.count == 0 {
            return Ok((site, Vec::new()));
        }
        let world: &dyn super::World = site.as_ref();
        let centres = place(world, &self.artifacts, self.seed);
        let radius_m = self.artifacts.radius_m;
        Ok((
            Arc::new(WithArtifacts::new(site, centres.clone(), radius_m)),
            centres,
        ))
    }

    fn build_site(&self) -> Result<Arc<dyn Site>, MeshError> {
        Ok(match self.kind {
            WorldKind::Cave => Arc::new(CaveWorld::generate(&self.cave, self.seed)),
            WorldKind::Warehouse => Arc::new(Warehouse::generate(&self.warehouse, self.seed)),
            WorldKind::Window => Arc::new(OpeningScene::window(&self.window, self.seed)),
            WorldKind::Door => Arc::new(OpeningScene::door(&self.door, self.seed)),
            WorldKind::OpenField => Arc::new(OpenField::generate(&self.open_field, self.seed)),
            WorldKind::Mesh => Arc::new(MeshWorld::load(&self.mesh, self.seed)?),
            WorldKind::TJunction => Arc::new(tunnels::t_junction(&self.tunnel, self.seed)),
            WorldKind::DeadEnd => Arc::new(tunnels::dead_end(&self.tunnel, self.seed)),
            WorldKind::Room => Arc::new(Room::generate(&self.room)),
        })
    }
}
