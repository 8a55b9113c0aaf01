//! Malformed meshes give an error naming the file and line (or the tet),
//! never a panic. Each case edits a valid file and states the expected error.

use crate::common;

use std::path::Path;

use common::{cube_tetgen, root, write_tetgen_text};
use skinpatch::mesh::io;

/// Reads a TetGen cube whose `.node`/`.ele` were edited, and checks the error.
fn check_tetgen(node: &str, ele: &str, expected: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let base = write_tetgen_text(dir.path(), "cube", node, ele);
    let err = match io::read_tetgen(&base) {
        Ok(_) => panic!("expected an error containing {expected:?}"),
        Err(e) => e.to_string(),
    };
    for part in expected {
        assert!(err.contains(part), "error {err:?} should contain {part:?}");
    }
}

fn edit(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "fixture lacks {from:?}");
    text.replacen(from, to, 1)
}

#[test]
fn tetgen_node_errors() {
    let (node, ele) = cube_tetgen();
    let cases: Vec<(String, Vec<&str>)> = vec![
        // Truncated: the header promises 8 points, the file ends after 5.
        (
            node.lines().take(7).collect::<Vec<_>>().join("\n"),
            vec!["cube.node:7:", "file ends early: expected point 6 of 8"],
        ),
        (
            String::new(),
            vec!["cube.node: file ends early", "expected the .node header"],
        ),
        (
            edit(&node, "3 1 1 0", "3 1 one 0"),
            vec!["cube.node:5:", "y: cannot parse 'one'"],
        ),
        (
            edit(&node, "6 1 0 1", "6 1 0 nan"),
            vec!["cube.node:8:", "z is not finite"],
        ),
        (
            edit(&node, "6 1 0 1", "6 1 0 inf"),
            vec!["cube.node:8:", "z is not finite"],
        ),
        (
            edit(&node, "5 0 0 1", "4 0 0 1"),
            vec!["cube.node:7:", "point index 4 out of sequence: expected 5"],
        ),
        (
            edit(&node, "2 1 0 0", "2 1 0"),
            vec!["cube.node:4:", "needs 4 fields, found 3"],
        ),
        (
            edit(&node, "8 3 0 0", "7 3 0 0"),
            vec!["cube.node:10:", "unexpected data after the 7 points"],
        ),
        (
            edit(&node, "8 3 0 0", "8 2 0 0"),
            vec!["cube.node:2:", "dimension must be 3"],
        ),
        (
            edit(&node, "1 0 0 0\n", "3 0 0 0\n"),
            vec!["cube.node:3:", "first point must be numbered 0 or 1"],
        ),
        (
            edit(&node, "8 3 0 0", "-8 3 0 0"),
            vec!["cube.node:2:", "number of points: cannot parse '-8'"],
        ),
        // A header claiming 4e9 points used to abort on the allocation
        // (96 GB); now the file just ends early.
        (
            edit(&node, "8 3 0 0", "4000000000 3 0 0"),
            vec![
                "cube.node:10:",
                "file ends early: expected point 9 of 4000000000",
            ],
        ),
        (
            edit(&node, "8 3 0 0", "8 3 18446744073709551615 0"),
            vec![
                "cube.node:3:",
                "a point line needs 18446744073709551615 fields",
            ],
        ),
    ];
    for (bad, expected) in cases {
        check_tetgen(&bad, &ele, &expected);
    }
}

#[test]
fn tetgen_ele_errors() {
    let (node, ele) = cube_tetgen();
    let cases: Vec<(String, Vec<&str>)> = vec![
        (
            edit(&ele, "6 4 1", "7 4 1"),
            vec![
                "cube.ele:7:",
                "file ends early: expected tetrahedron 7 of 7",
            ],
        ),
        (
            edit(&ele, "6 4 1", "4000000000 4 1"),
            vec![
                "cube.ele:",
                "file ends early: expected tetrahedron 7 of 4000000000",
            ],
        ),
        (
            edit(&ele, "6 4 1", "5 4 1"),
            vec!["cube.ele:7:", "unexpected data after the 5 tetrahedra"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 3 x 7 5"),
            vec!["cube.ele:3:", "vertex index: cannot parse 'x'"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 3 9 7 5"),
            vec!["cube.ele:3:", "vertex index 9 out of range"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 3 0 7 5"),
            vec!["cube.ele:3:", "vertex index 0 out of range"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "1 1 3 4 7 5"),
            vec!["cube.ele:3:", "tetrahedron index 1 out of sequence"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 3 4 7 5.5"),
            vec!["cube.ele:3:", "region attribute must be an integer"],
        ),
        (
            edit(&ele, "6 4 1", "6 5 1"),
            vec!["cube.ele:1:", "nodes per tetrahedron must be 4 or 10"],
        ),
        // Structural errors name the tet (0-based index).
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 3 3 7 5"),
            vec!["cube.ele", "tet 1 repeats vertex 2"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 7 4 3 5"),
            vec!["cube.ele", "tet 1 is inverted"],
        ),
        (
            edit(&ele, "2 1 3 4 7 5", "2 1 2 3 4 5"),
            vec!["cube.ele", "tet 1 is degenerate"],
        ),
        (
            format!("# region 9 skin\n{ele}"),
            vec!["cube.ele", "region 'skin' (id 9) has no tetrahedra"],
        ),
        // Two tets on the same face as a third: non-manifold.
        (
            edit(&ele, "6 4 1", "7 4 1") + "7 1 2 3 7 5\n",
            vec!["cube.ele", "shared by more than two tets"],
        ),
    ];
    for (bad, expected) in cases {
        check_tetgen(&node, &bad, &expected);
    }
}

#[test]
fn tetgen_face_errors() {
    let (node, ele) = cube_tetgen();
    let dir = tempfile::tempdir().unwrap();
    let base = write_tetgen_text(dir.path(), "cube", &node, &ele);
    for (face, expected) in [
        (
            "2 1\n1 5 6 7 2\n",
            "cube.face:2: file ends early: expected face 2 of 2",
        ),
        (
            "1 1\n1 5 6 99 2\n",
            "cube.face:2: vertex index 99 out of range",
        ),
        (
            "1 1\n1 5 6 7\n",
            "cube.face:2: a face line needs 5 fields, found 4",
        ),
        ("1 1\n1 5 5 7 2\n", "cube.face:2: face repeats a vertex"),
        (
            "1 2\n",
            "cube.face:1: boundary marker flag must be 0 or 1, got '2'",
        ),
        (
            "2 1\n1 5 6 7 2\n2 7 6 5 2\n",
            "cube.face:3: the same face is listed twice",
        ),
    ] {
        std::fs::write(dir.path().join("cube.face"), face).unwrap();
        let err = io::read_tetgen(&base).unwrap_err().to_string();
        assert!(
            err.contains(expected),
            "{err:?} should contain {expected:?}"
        );
    }
}

#[test]
fn missing_and_unknown_files() {
    let err = io::read_mesh(Path::new("/nonexistent/mesh.msh"))
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("/nonexistent/mesh.msh:"), "{err}");
    let err = io::read_mesh(Path::new("/nonexistent/mesh.node"))
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("/nonexistent/mesh.node:"), "{err}");
    let err = io::read_mesh(Path::new("mesh.stl"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("unknown mesh format"), "{err}");
    let err = io::read_vtu(Path::new("/nonexistent/a.vtu"))
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("/nonexistent/a.vtu:"), "{err}");
}

#[test]
fn binary_garbage_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("junk.msh");
    std::fs::write(&path, [0u8, 159, 146, 150, 10, 255]).unwrap();
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(err.contains("junk.msh:1: not a text file"), "{err}");
    let vtu = dir.path().join("junk.vtu");
    std::fs::write(&vtu, "<VTKFile><nonsense").unwrap();
    let err = io::read_vtu(&vtu).unwrap_err().to_string();
    assert!(err.contains("junk.vtu"), "{err}");
}

/// Edits the Gmsh fixture and checks the error.
fn check_gmsh(edit_fn: impl Fn(&str) -> String, expected: &[&str]) {
    let text = std::fs::read_to_string(root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("box.msh");
    std::fs::write(&path, edit_fn(&text)).unwrap();
    let err = match io::read_mesh(&path) {
        Ok(_) => panic!("expected an error containing {expected:?}"),
        Err(e) => e.to_string(),
    };
    for part in expected {
        assert!(err.contains(part), "error {err:?} should contain {part:?}");
    }
}

/// 1-based line number of the first line equal to `line` in the fixture.
fn fixture_line(line: &str) -> usize {
    let text = std::fs::read_to_string(root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    1 + text.lines().position(|l| l.trim() == line).unwrap()
}

#[test]
fn gmsh_errors() {
    let nodes = fixture_line("$Nodes");
    let elements = fixture_line("$Elements");
    check_gmsh(
        |t| t.lines().take(elements + 10).collect::<Vec<_>>().join("\n"),
        &["box.msh:", "file ends early: expected an element"],
    );
    check_gmsh(|_| String::new(), &["box.msh: empty file"]);
    check_gmsh(
        |t| t.replacen("4.1 0 8", "4.0 0 8", 1),
        &[
            "box.msh:2:",
            "MSH version 4.0 is not supported; save as 4.1 or 2.2",
        ],
    );
    check_gmsh(
        |t| t.replacen("4.1 0 8", "4.1 2 8", 1),
        &["box.msh:2:", "file type '2' is neither 0 nor 1"],
    );
    check_gmsh(
        |t| t.replacen("4.1 0 8", "4.1 0 4", 1),
        &["box.msh:2:", "data size 4 is not supported"],
    );
    // A text file that says it is binary: the marker after the format line
    // is text, not the integer 1.
    check_gmsh(
        |t| t.replacen("4.1 0 8", "4.1 1 8", 1),
        &["box.msh: byte 20: the endianness marker is not the integer 1"],
    );
    check_gmsh(
        |t| t.replacen("$MeshFormat", "$Mesh", 1),
        &["box.msh:1:", "must start with $MeshFormat"],
    );
    check_gmsh(
        |t| t.replacen("$EndNodes", "$EndNodez", 1),
        &["expected $EndNodes, got '$EndNodez'"],
    );
    // The $Nodes header's node count.
    let nodes_header = format!("{}:", nodes + 1);
    check_gmsh(
        |t| {
            let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
            let f: Vec<&str> = lines[nodes].split_whitespace().collect();
            let n: usize = f[1].parse().unwrap();
            lines[nodes] = format!("{} {} {} {}", f[0], n + 1, f[2], f[3]);
            lines.join("\n")
        },
        &[&nodes_header, "header announces"],
    );
    check_gmsh(
        |t| {
            let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
            let f: Vec<&str> = lines[elements].split_whitespace().collect();
            let n: usize = f[1].parse().unwrap();
            lines[elements] = format!("{} {} {} {}", f[0], n - 1, f[2], f[3]);
            lines.join("\n")
        },
        &["exceed the", "the section header (line"],
    );
    // A non-numeric coordinate and a NaN, on the first coordinate line of block 1.
    check_gmsh(|t| replace_coordinate(t, "abc"), &["x: cannot parse 'abc'"]);
    check_gmsh(|t| replace_coordinate(t, "nan"), &["x is not finite"]);
    // A tet referring to a node that does not exist, and a repeated node tag.
    check_gmsh(
        |t| replace_last_tet_node(t, "999999"),
        &["element", "refers to node 999999, which is not defined"],
    );
    check_gmsh(
        |t| {
            t.replacen("3 1 \"dermis\"", "3 1 \"dermis\"\n3 7 \"skin\"", 1)
                .replacen("\n2\n3 1", "\n3\n3 1", 1)
        },
        &["region 'skin' (id 7) has no tetrahedra"],
    );
}

/// A block count that does not match the block's lines is named at the
/// block, not blamed on the line read next as if it were a header (a count
/// one short read the next element's node tags as "element type 11,
/// second-order tetrahedra"); Gmsh 2.2's count likewise.
#[test]
fn gmsh_counts_that_do_not_match_name_the_block() {
    let elements = fixture_line("$Elements");
    let block = elements + 2;
    let header = "3 1 4 454";
    assert_eq!(fixture_line(header), block);
    // One short: the 454th element is read where the next header should be.
    check_gmsh(
        |t| t.replacen(header, "3 1 4 453", 1),
        &[
            &format!("box.msh:{}:", block + 454),
            "element block header: 5 values on the line, where a header has 4",
            &format!("the block before it (line {block}) holds more than the 453 elements"),
        ],
    );
    // One over: the next block's header is read as an element.
    check_gmsh(
        |t| t.replacen(header, "3 1 4 455", 1),
        &[
            &format!("box.msh:{}:", block + 455),
            "an element of type 4 is a line of 5 values",
            &format!("the block (line {block}) declares 455 elements"),
        ],
    );
    // More than the section header announces.
    check_gmsh(
        |t| t.replacen("2 1144 1 1144", "2 1000 1 1144", 1),
        &[
            &format!("box.msh:{}:", block + 455),
            "690 elements here and 454 in the blocks before exceed the 1000",
            &format!("the section header (line {}) announces", elements + 1),
        ],
    );
    // Gmsh 2.2: one element a line, the count in the section header.
    let mesh = io::read_mesh(&root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let text = String::from_utf8(crate::mesh_io::encode_msh(&mesh, false, false, false)).unwrap();
    let at = text.find("$Elements\n").unwrap() + "$Elements\n".len();
    let end = at + text[at..].find('\n').unwrap();
    let count: usize = text[at..end].trim().parse().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("box22.msh");
    std::fs::write(
        &path,
        format!("{}{}{}", &text[..at], count - 1, &text[end..]),
    )
    .unwrap();
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(
        err.contains("expected $EndElements")
            && err.contains("the section holds more than its header announces"),
        "{err}"
    );
}

/// Replaces the x coordinate of the first node of the first non-empty node block.
fn replace_coordinate(text: &str, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let start = lines.iter().position(|l| l == "$Nodes").unwrap() + 2;
    let mut i = start;
    loop {
        let f: Vec<usize> = lines[i]
            .split_whitespace()
            .map(|s| s.parse().unwrap())
            .collect();
        let n = f[3];
        if n > 0 {
            let coord = i + 1 + n;
            let rest: Vec<String> = lines[coord]
                .split_whitespace()
                .skip(1)
                .map(str::to_string)
                .collect();
            lines[coord] = format!("{value} {}", rest.join(" "));
            return lines.join("\n");
        }
        i += 1;
    }
}

/// Replaces the last node of the last tetrahedron.
fn replace_last_tet_node(text: &str, tag: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let end = lines.iter().position(|l| l == "$EndElements").unwrap();
    let mut f: Vec<String> = lines[end - 1]
        .split_whitespace()
        .map(str::to_string)
        .collect();
    *f.last_mut().unwrap() = tag.to_string();
    lines[end - 1] = f.join(" ");
    lines.join("\n")
}

/// A FIFO (or any non-regular file) as an input is refused at once instead
/// of blocking the read forever; the message names the file.
#[cfg(unix)]
#[test]
fn a_fifo_is_not_read() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["patch.node", "scenario.toml", "map.png"] {
        let fifo = dir.path().join(name);
        let status = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo runs");
        assert!(status.success());
        let err = match name {
            "patch.node" => io::read_mesh(&fifo).map(|_| ()).unwrap_err(),
            "scenario.toml" => skinpatch::scenario::Scenario::load(&fifo)
                .map(|_| ())
                .unwrap_err(),
            _ => skinpatch::micro::io::read_map(
                &fifo,
                &skinpatch::micro::io::MapDefaults {
                    texel: skinpatch::micro::io::TexelSize::Um(1.0),
                    height_unit_um: 1.0,
                    edge: skinpatch::micro::Edge::Clamp,
                },
            )
            .map(|_| ())
            .unwrap_err(),
        }
        .to_string();
        assert!(
            err.contains(name) && err.contains("not a regular file"),
            "{err}"
        );
    }
    // A folder is refused as such.
    let err = skinpatch::scenario::Scenario::load(dir.path()).unwrap_err();
    assert!(err.to_string().contains("is a folder"), "{err}");
}
