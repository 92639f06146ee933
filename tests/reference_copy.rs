//! The repository carries its own copy of the reference data (`reference/`), so that a clone stands
//! alone; where the project's upstream copy (`../shared/reference/`) is beside the clone, the two
//! must be the same, byte for byte.

mod common;

#[test]
fn reference_copies_match_shared_when_present() {
    let mut compared = 0;
    for name in ["published-figures.toml", "irb120.toml"] {
        let ours = std::fs::read(common::reference(name)).unwrap_or_else(|e| panic!("reference/{name}: {e}"));
        assert!(!ours.is_empty(), "reference/{name} is empty");
        match common::shared_reference(name) {
            Some(p) => {
                let theirs = std::fs::read(&p).unwrap();
                assert!(ours == theirs, "reference/{name} differs from {}: copy the upstream file into reference/", p.display());
                compared += 1;
            }
            None => eprintln!("../shared/reference/{name} is not beside the clone: the repository's copy is used as it is"),
        }
    }
    eprintln!("{compared} reference files compared with ../shared/reference");
}
