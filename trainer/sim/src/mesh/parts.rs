//! Several bodies in one mesh: the parts' vertices and elements side by side, with no
//! element joining two parts. The solver steps them together; contact between them is the
//! mesh's self-contact (`[contact] self = true`).

use super::{Elements, Mesh};

/// The parts as one mesh, vertices numbered part after part. All parts must be the same
/// kind of body (tets, 2D triangles, cloth or rods); the error says which part differs.
/// Region attributes are kept only where every part has them.
pub fn concat(parts: Vec<Mesh>) -> Result<Mesh, String> {
    let mut parts = parts.into_iter();
    let Some(mut out) = parts.next() else {
        return Err("needs at least one part".into());
    };
    for (k, part) in parts.enumerate() {
        let offset = out.num_vertices();
        let shifted = |v: &usize| v + offset;
        match (&mut out.elements, part.elements) {
            (Elements::Tets(a), Elements::Tets(b)) => a.extend(b.iter().map(|t| t.map(|v| shifted(&v)))),
            (Elements::Triangles(a), Elements::Triangles(b)) | (Elements::Shell(a), Elements::Shell(b)) => {
                a.extend(b.iter().map(|t| t.map(|v| shifted(&v))))
            }
            (Elements::Rods(a), Elements::Rods(b)) => a.extend(b.iter().map(|r| r.iter().map(shifted).collect())),
            (first, other) => {
                return Err(format!(
                    "part {} is {} but part 0 is {}",
                    k + 1,
                    kind_name(&other),
                    kind_name(first)
                ));
            }
        }
        out.rest.extend_from_slice(&part.rest);
        out.attributes = match (out.attributes.take(), part.attributes) {
            (Some(mut a), Some(b)) => {
                a.extend(b);
                Some(a)
            }
            _ => None,
        };
    }
    Ok(out)
}

fn kind_name(e: &Elements) -> &'static str {
    match e {
        Elements::Tets(_) => "a tet mesh",
        Elements::Triangles(_) => "a 2D triangle mesh",
        Elements::Shell(_) => "cloth",
        Elements::Rods(_) => "rods",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::procedural::{box_tets, cloth_grid};

    #[test]
    fn parts_keep_their_elements_and_never_share_a_vertex() {
        let a = box_tets([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
        let b = box_tets([2.0, 0.0, 0.0], [3.0, 1.0, 1.0], [2, 1, 1]).unwrap();
        let (na, nb) = (a.num_vertices(), b.num_vertices());
        let (ea, eb) = (a.num_elements(), b.num_elements());
        let m = concat(vec![a.clone(), b.clone()]).unwrap();
        assert_eq!(m.num_vertices(), na + nb);
        assert_eq!(m.num_elements(), ea + eb);
        assert_eq!(&m.rest[..a.rest.len()], &a.rest[..]);
        assert_eq!(&m.rest[a.rest.len()..], &b.rest[..]);
        let Elements::Tets(t) = &m.elements else { panic!("tets") };
        // The first part's tets touch only its vertices, the second's only the others.
        assert!(t[..ea].iter().flatten().all(|&v| v < na));
        assert!(t[ea..].iter().flatten().all(|&v| v >= na && v < na + nb));
        let Elements::Tets(tb) = &b.elements else {
            panic!("tets")
        };
        assert_eq!(t[ea], tb[0].map(|v| v + na));
    }

    #[test]
    fn parts_of_different_kinds_are_refused_naming_the_part() {
        let a = box_tets([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
        let c = cloth_grid([1.0, 1.0], [3, 3], [0.0; 3], ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0])).unwrap();
        let err = concat(vec![a.clone(), a, c]).unwrap_err();
        assert!(err.contains("part 2 is cloth"), "{err}");
        assert!(concat(Vec::new()).is_err());
    }
}
