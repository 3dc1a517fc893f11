//! Surface extraction for CSG intersections, subtractions and smooth unions.

use glam::DVec3;
use marchmesh_scene::Node;

use crate::MeshError;
use crate::tessellate::LocalMesh;

/// Extracts the surface of a composite node in its local frame.
pub(crate) fn extract(
    node: &Node,
    _bounds: Option<(DVec3, DVec3)>,
    _resolution: u32,
) -> Result<LocalMesh, MeshError> {
    Err(MeshError::Unsupported {
        json_path: node.json_path.clone(),
        reason: "CSG surface extraction needs the shared distance-field crate (marchmesh-field), which is not available yet".into(),
    })
}
