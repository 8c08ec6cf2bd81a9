//! The fixed decomposition: coverage, balance, connectivity and the interface weights.

use super::fixtures::beam;
use crate::adaptive::partition::{element_vertices, Partition, PartitionError};
use crate::mesh::procedural::cloth_grid;
use crate::mesh::{Elements, Mesh};

/// Whether `members` (vertices or elements) form one connected piece, two members being
/// adjacent when `linked` says so.
fn connected(members: &[usize], linked: impl Fn(usize, usize) -> bool) -> bool {
    let mut reached = vec![false; members.len()];
    let mut stack = vec![0];
    reached[0] = true;
    while let Some(i) = stack.pop() {
        for j in 0..members.len() {
            if !reached[j] && linked(members[i], members[j]) {
                reached[j] = true;
                stack.push(j);
            }
        }
    }
    reached.iter().all(|&r| r)
}

/// Largest subdomain over the mean allowed for vertices: METIS's default imbalance
/// tolerance is 1.03.
const VERTEX_BALANCE: f64 = 1.05;
/// The same for elements, assigned by majority after the vertices are split (measured up
/// to 1.15 on these meshes).
const ELEMENT_BALANCE: f64 = 1.3;

/// Checks coverage, balance (largest part over the mean within [`VERTEX_BALANCE`] and
/// [`ELEMENT_BALANCE`]), connectivity and the weights of a partition of `mesh` into `parts`.
fn check_partition(mesh: &Mesh, parts: usize) -> Partition {
    let partition = Partition::new(mesh, parts).expect("partition");
    let n = mesh.num_vertices();
    let elements = element_vertices(&mesh.elements);
    assert_eq!(partition.num_subdomains(), parts);
    assert_eq!(partition.vertex_subdomains().len(), n);
    assert_eq!(partition.element_subdomains().len(), elements.len());
    assert!(partition.vertex_subdomains().iter().all(|&p| p < parts));
    assert!(partition.element_subdomains().iter().all(|&p| p < parts));
    let mut vertex_count = 0;
    let mut element_count = 0;
    for l in 0..parts {
        assert!(partition
            .vertices(l)
            .iter()
            .all(|&v| partition.vertex_subdomains()[v] == l));
        assert!(partition
            .elements(l)
            .iter()
            .all(|&e| partition.element_subdomains()[e] == l));
        vertex_count += partition.vertices(l).len();
        element_count += partition.elements(l).len();
    }
    assert_eq!((vertex_count, element_count), (n, elements.len()));

    let largest = |sizes: Vec<usize>, total: usize| *sizes.iter().max().unwrap() as f64 / (total as f64 / parts as f64);
    let v_ratio = largest((0..parts).map(|l| partition.vertices(l).len()).collect(), n);
    let e_ratio = largest(
        (0..parts).map(|l| partition.elements(l).len()).collect(),
        elements.len(),
    );
    assert!(
        v_ratio <= VERTEX_BALANCE && e_ratio <= ELEMENT_BALANCE,
        "imbalance: vertices {v_ratio}, elements {e_ratio}"
    );

    let edges = mesh.edges();
    for l in 0..parts {
        let vertices = partition.vertices(l);
        assert!(
            connected(vertices, |a, b| edges.binary_search(&[a.min(b), a.max(b)]).is_ok()),
            "vertex subdomain {l} is in pieces"
        );
        let share = |e: usize, f: usize| elements[e].iter().any(|v| elements[f].contains(v));
        assert!(
            connected(partition.elements(l), share),
            "element subdomain {l} is in pieces"
        );
    }

    // Every element belongs to the subdomain holding most of its vertices.
    for (e, verts) in elements.iter().enumerate() {
        let l = partition.element_subdomains()[e];
        let count = |p: usize| verts.iter().filter(|&&v| partition.vertex_subdomains()[v] == p).count();
        assert!(
            verts
                .iter()
                .all(|&v| count(partition.vertex_subdomains()[v]) <= count(l)),
            "element {e}"
        );
    }
    partition
}

#[test]
fn beam_partition_is_complete_balanced_and_connected() {
    let mesh = beam([16, 4, 4]);
    for parts in [2, 5, 8] {
        check_partition(&mesh, parts);
    }
}

#[test]
fn cloth_partition_is_complete_balanced_and_connected() {
    let mesh = cloth_grid([2.0, 1.0], [21, 11], [0.0; 3], ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])).expect("cloth");
    check_partition(&mesh, 6);
}

#[test]
fn partition_is_reproducible_and_one_part_takes_everything() {
    let mesh = beam([8, 2, 2]);
    let a = Partition::new(&mesh, 4).expect("partition");
    let b = Partition::new(&mesh, 4).expect("partition");
    assert_eq!(a.vertex_subdomains(), b.vertex_subdomains());
    assert_eq!(a.element_subdomains(), b.element_subdomains());
    let one = check_partition(&mesh, 1);
    assert!(one.vertex_subdomains().iter().all(|&l| l == 0));
}

#[test]
fn concurrent_partitions_are_identical() {
    let mesh = beam([12, 3, 3]);
    let reference = Partition::new(&mesh, 6).expect("partition");
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..4)
            .map(|_| {
                scope.spawn(|| {
                    (0..5)
                        .map(|_| {
                            Partition::new(&mesh, 6)
                                .expect("partition")
                                .vertex_subdomains()
                                .to_vec()
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for worker in workers {
            for parts in worker.join().expect("worker") {
                assert_eq!(parts, reference.vertex_subdomains());
            }
        }
    });
}

#[test]
fn bad_part_counts_and_vertex_indices_are_errors() {
    let mesh = beam([2, 1, 1]);
    let n = mesh.num_vertices();
    assert_eq!(
        Partition::new(&mesh, 0).expect_err("no parts"),
        PartitionError::Parts { parts: 0, vertices: n }
    );
    assert_eq!(
        Partition::new(&mesh, n + 1).expect_err("too many parts"),
        PartitionError::Parts {
            parts: n + 1,
            vertices: n
        }
    );
    let mut broken = mesh.clone();
    if let Elements::Tets(tets) = &mut broken.elements {
        tets[1][2] = n + 5;
    }
    let err = Partition::new(&broken, 2).expect_err("bad index");
    assert_eq!(
        err,
        PartitionError::VertexOutOfRange {
            element: 1,
            vertex: n + 5,
            vertices: n
        }
    );
    assert!(err.to_string().contains("element 1"));
}

#[test]
fn isolated_vertices_get_a_subdomain() {
    let mut mesh = beam([4, 1, 1]);
    mesh.rest.extend_from_slice(&[9.0, 9.0, 9.0]);
    let partition = Partition::new(&mesh, 3).expect("partition");
    let v = mesh.num_vertices() - 1;
    let l = partition.vertex_subdomains()[v];
    assert!(partition.vertices(l).contains(&v));
}
