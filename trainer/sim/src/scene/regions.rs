//! Material regions: per-element materials from `[[material.regions]]`, each selecting
//! elements by the box their centroid lies in or by the attribute the mesh file gives them.

use std::collections::BTreeSet;

use super::{MaterialSpec, RegionSpec, Scene};
use crate::error::InputError;
use crate::material::ElementMaterial;
use crate::mesh::{Elements, Mesh};

/// Which elements a region takes.
enum Select {
    Box(super::BoxSpec),
    Attribute(i64),
}

impl RegionSpec {
    /// The region's selector, or why it has none (exactly one of `box` and `attribute`).
    fn selector(&self) -> Result<Select, &'static str> {
        match (self.bounds, self.attribute) {
            (Some(b), None) => Ok(Select::Box(b)),
            (None, Some(a)) => Ok(Select::Attribute(a)),
            (Some(_), Some(_)) => Err("has both `box` and `attribute`; a region selects by exactly one"),
            (None, None) => Err("needs `box` (element centroids in a box) or `attribute` (a mesh file attribute)"),
        }
    }
}

/// Checks that every region of `m` selects by exactly one of `box` and `attribute`; the error
/// is the field and the message.
pub(super) fn check_selectors(m: &MaterialSpec) -> Result<(), (String, String)> {
    for (k, r) in m.regions.iter().enumerate() {
        r.selector()
            .map_err(|msg| (format!("material.regions[{k}]"), msg.to_string()))?;
    }
    Ok(())
}

/// The sorted distinct attribute values of `mesh`'s elements.
fn attribute_values(mesh: &Mesh) -> BTreeSet<i64> {
    mesh.attributes.iter().flatten().copied().collect()
}

/// `values` as `1, 2, 5`.
fn list(values: impl IntoIterator<Item = i64>) -> String {
    values.into_iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", ")
}

impl Scene {
    /// Per-element materials (per strand for rods): the base material, then each region's
    /// overrides in order for the elements it selects (centroid in its box, or its attribute).
    /// A single material when there are no regions. An attribute region on a mesh without
    /// attributes, or naming an attribute no element has, is an error naming the field.
    pub fn element_materials(&self, mesh: &Mesh) -> Result<Vec<ElementMaterial>, InputError> {
        let m = &self.material;
        let base = ElementMaterial {
            youngs: m.youngs,
            poisson: m.poisson,
            density: m.density,
        };
        if m.regions.is_empty() {
            return Ok(vec![base]);
        }
        let groups: Vec<&[usize]> = match &mesh.elements {
            Elements::Tets(t) => t.iter().map(|e| e.as_slice()).collect(),
            Elements::Triangles(t) | Elements::Shell(t) => t.iter().map(|e| e.as_slice()).collect(),
            Elements::Rods(s) => s.iter().map(|e| e.as_slice()).collect(),
        };
        let mut materials = vec![base; groups.len()];
        for (k, region) in m.regions.iter().enumerate() {
            let selector = region
                .selector()
                .map_err(|msg| self.field_error(format!("material.regions[{k}]"), msg))?;
            let selected: Vec<bool> = match selector {
                Select::Box(b) => groups.iter().map(|verts| b.contains(centroid(mesh, verts))).collect(),
                Select::Attribute(a) => {
                    let field = format!("material.regions[{k}].attribute");
                    let Some(attributes) = &mesh.attributes else {
                        return Err(self.field_error(
                            field,
                            "the mesh has no element attributes (only TetGen / Triangle `.ele` files \
                             with attributes and MEDIT files have them)",
                        ));
                    };
                    if !attributes.contains(&a) {
                        return Err(self.field_error(
                            field,
                            format!(
                                "no element has attribute {a}; the mesh's attributes are {}",
                                list(attribute_values(mesh))
                            ),
                        ));
                    }
                    attributes.iter().map(|&x| x == a).collect()
                }
            };
            for (e, _) in materials.iter_mut().zip(&selected).filter(|(_, &s)| s) {
                e.youngs = region.youngs.unwrap_or(e.youngs);
                e.poisson = region.poisson.unwrap_or(e.poisson);
                e.density = region.density.unwrap_or(e.density);
            }
        }
        Ok(materials)
    }

    /// Warnings about the scene's mesh file: element attributes that no `attribute` region
    /// uses, so those elements silently get the base material. A file whose elements all have
    /// one attribute (a homogeneous body, e.g. MEDIT references all 0) gets none.
    pub fn region_warnings(&self, mesh: &Mesh) -> Vec<String> {
        let values = attribute_values(mesh);
        if values.len() < 2 {
            return Vec::new();
        }
        let used: BTreeSet<i64> = self.material.regions.iter().filter_map(|r| r.attribute).collect();
        let unused: Vec<i64> = values.difference(&used).copied().collect();
        if unused.is_empty() {
            return Vec::new();
        }
        let file = match &self.mesh {
            super::MeshSpec::File { path, .. } => self.source.parent().unwrap_or(".".as_ref()).join(path),
            _ => self.source.clone(),
        };
        vec![format!(
            "{}: element attribute{} {} used by no `[[material.regions]]` in {}: those elements \
             get the base material",
            file.display(),
            if unused.len() == 1 { "" } else { "s" },
            if unused.len() == 1 {
                format!("{} is", list(unused))
            } else {
                format!("{} are", list(unused))
            },
            self.source.display()
        )]
    }
}

/// Centroid of the vertices `verts` of `mesh`, padded to 3D.
fn centroid(mesh: &Mesh, verts: &[usize]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for &v in verts {
        let p = &mesh.rest[v * mesh.dim..(v + 1) * mesh.dim];
        for (ci, pi) in c.iter_mut().zip(p) {
            *ci += pi / verts.len() as f64;
        }
    }
    c
}
