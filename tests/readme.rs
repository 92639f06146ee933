//! The README as a guide: at most 250 lines, every file it and the docs link to exists, and every
//! command of its shell blocks is one that CI runs (`scripts/ci/readme_commands.py` runs the
//! calsim commands with the release binary; the others must be lines of `.ci/run`).

mod common;

use std::path::Path;

fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let end = rest.find(')').unwrap_or(rest.len());
        out.push(rest[..end].to_string());
    }
    out
}

#[test]
fn the_readme_has_at_most_250_lines() {
    let text = std::fs::read_to_string(common::repo().join("README.md")).expect("README.md");
    let lines = text.lines().count();
    assert!(lines <= 250, "README.md has {lines} lines");
}

#[test]
fn every_file_the_readme_and_the_docs_link_to_exists() {
    let repo = common::repo();
    let mut pages = vec![repo.join("README.md"), repo.join("results/README.md"), repo.join("python/README.md")];
    for entry in std::fs::read_dir(repo.join("docs")).expect("docs/") {
        let p = entry.expect("an entry").path();
        if p.extension().is_some_and(|e| e == "md") {
            pages.push(p);
        }
    }
    for page in pages {
        let text = std::fs::read_to_string(&page).expect("a page");
        let dir = page.parent().unwrap_or(Path::new("."));
        for link in links(&text) {
            if link.starts_with("http") || link.starts_with('#') || link.is_empty() {
                continue;
            }
            let file = link.split('#').next().unwrap_or_default();
            assert!(dir.join(file).exists(), "{}: link to {link}: no such file", page.display());
        }
    }
}

#[test]
fn every_shell_command_of_the_readme_is_one_ci_runs() {
    let repo = common::repo();
    let readme = std::fs::read_to_string(repo.join("README.md")).expect("README.md");
    let ci = std::fs::read_to_string(repo.join(".ci/run")).expect(".ci/run");
    assert!(ci.contains("scripts/ci/readme_commands.py"), ".ci/run does not run the README's commands");
    assert!(ci.contains("scripts/ci/doc_numbers.py"), ".ci/run does not compare the documented numbers with their commands");
    let script = std::fs::read_to_string(repo.join("scripts/ci/readme_commands.py")).expect("the script");
    let mut count = 0;
    for block in readme.split("```sh\n").skip(1) {
        let block = block.split("```").next().unwrap_or_default();
        for line in block.lines() {
            let line = line.split("  #").next().unwrap_or_default().trim();
            if line.is_empty() {
                continue;
            }
            count += 1;
            let calsim = line.starts_with("calsim ") || line.starts_with("cargo run --release -- ");
            assert!(
                calsim || script.contains(&format!("{line:?}")) || script.contains(&format!("'{line}'")),
                "README: {line:?} is run by no CI step"
            );
        }
    }
    assert!(count >= 10, "the README shows {count} commands");
}

/// The quick start's output block is what its first command prints, line for line: the study of
/// `scenarios/irb120_trical.toml` run as the README runs it (the figures and the recording skipped,
/// which changes no printed line), its stdout the block line for line, the wall times (which vary)
/// written `timing: ...`.
#[test]
fn the_quick_start_output_is_what_the_command_prints() {
    let readme = std::fs::read_to_string(common::repo().join("README.md")).expect("README.md");
    let quick = readme.split("## Quick start").nth(1).expect("a Quick start section");
    assert!(quick.contains("cargo run --release -- run scenarios/irb120_trical.toml"), "the quick start runs another command");
    let block = quick.split("```text\n").nth(1).and_then(|b| b.split("```").next()).expect("an output block in the Quick start");
    let tmp = common::scratch("readme");
    let out = common::calsim()
        .args(["run", "scenarios/irb120_trical.toml", "--no-plots", "--no-recording", "--out"])
        .arg(tmp.path())
        .output()
        .expect("calsim runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8(out.stdout).expect("UTF-8");
    let (printed, timing) = stdout.trim_end().rsplit_once('\n').expect("more than one line");
    assert!(timing.starts_with("timing: study ") && timing.contains("results written in"), "last line: {timing}");
    let block = block.trim_end().strip_suffix("timing: ...").expect("the block ends with the line of wall times, `timing: ...`");
    let (printed, block) = (printed.trim_end(), block.trim_end());
    for (k, (a, b)) in printed.lines().zip(block.lines()).enumerate() {
        assert_eq!(a, b, "line {} of the README's output block differs from what the command prints", k + 1);
    }
    assert_eq!(printed.lines().count(), block.lines().count(), "the command prints:\n{printed}");
    // One world is one draw: no verdict, and another study's rows say so.
    assert!(!printed.contains("MISS") && !printed.lines().any(|l| l.ends_with(" pass")), "{printed}");
    let table8: Vec<&str> =
        printed.lines().filter(|l| l.starts_with("Table 8, laser tracker") || l.starts_with("Table 8, optical CMM")).collect();
    assert_eq!(table8.len(), 6, "{printed}");
    assert!(table8.iter().all(|l| l.ends_with("another study, ref. [9]")), "{table8:?}");
}
