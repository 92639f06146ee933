//! The link tree of a URDF, checked as a whole before the chain is read from it: every link and
//! joint named once, every joint between two links the file defines, one root, every link reached
//! from it (no detached cycle or second tree), and a size an arm has. The chain walk and the
//! bodies then read a tree: each link's joints to its children, and whether an actuated joint lies
//! below it, both found once here (no walk repeats a search over the file).

use std::collections::{HashMap, HashSet};

use super::chain::actuated;

/// Most links (and most joints) of a URDF calsim converts: an arm with its tools, sensors and
/// passive linkages has tens; a whole humanoid a few hundred.
pub const MOST_LINKS: usize = 1000;

/// A URDF's links as a checked tree.
pub(super) struct Tree<'a> {
    /// The root link.
    pub root: &'a str,
    /// Each link's joints to its children, in file order.
    pub children: HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    /// The links below which (strictly) an actuated joint lies.
    pub drives: HashSet<&'a str>,
}

impl<'a> Tree<'a> {
    /// The joints from `link` to its children.
    pub fn children(&self, link: &str) -> &[&'a urdf_rs::Joint] {
        self.children.get(link).map_or(&[], Vec::as_slice)
    }

    /// Whether the subtree below `link` holds an actuated joint.
    pub fn drives(&self, link: &str) -> bool {
        self.drives.contains(link)
    }
}

/// At most five of `names`, then how many more: a list for a one-line message.
pub(super) fn few<'n>(names: impl IntoIterator<Item = &'n str>) -> String {
    let all: Vec<&str> = names.into_iter().collect();
    let shown: Vec<String> = all.iter().take(5).map(|n| format!("`{}`", crate::io::names::escape_controls(n))).collect();
    match all.len() {
        0..=5 => shown.join(", "),
        n => format!("{} and {} more", shown.join(", "), n - 5),
    }
}

/// The first name of `names` given twice.
fn twice<'n>(names: impl IntoIterator<Item = &'n str>) -> Option<&'n str> {
    let mut seen = HashSet::new();
    names.into_iter().find(|n| !seen.insert(*n))
}

/// Checks the links and joints of `robot` as one tree (see the module) and returns it.
pub(super) fn tree(robot: &urdf_rs::Robot) -> Result<Tree<'_>, String> {
    let (links, joints) = (robot.links.len(), robot.joints.len());
    if links > MOST_LINKS || joints > MOST_LINKS {
        return Err(format!("{links} links and {joints} joints: an arm has at most {MOST_LINKS} of each"));
    }
    if let Some(l) = twice(robot.links.iter().map(|l| l.name.as_str())) {
        return Err(format!("two links named {}: every link needs a name of its own", few([l])));
    }
    if let Some(j) = twice(robot.joints.iter().map(|j| j.name.as_str())) {
        return Err(format!("two joints named {}: every joint needs a name of its own", few([j])));
    }
    let defined: HashSet<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
    let mut parent_of: HashMap<&str, &urdf_rs::Joint> = HashMap::new();
    let mut children: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
    for j in &robot.joints {
        let (parent, child) = (j.parent.link.as_str(), j.child.link.as_str());
        for (role, link) in [("parent", parent), ("child", child)] {
            if !defined.contains(link) {
                return Err(format!(
                    "joint {}: its {role} link {} is not defined (no <link name=...> of that name)",
                    few([j.name.as_str()]),
                    few([link])
                ));
            }
        }
        if parent == child {
            return Err(format!("joint {} joins link {} to itself", few([j.name.as_str()]), few([child])));
        }
        if let Some(first) = parent_of.insert(child, j) {
            return Err(format!(
                "link {} is the child of two joints ({}): not a serial chain",
                few([child]),
                few([first.name.as_str(), j.name.as_str()])
            ));
        }
        children.entry(parent).or_default().push(j);
    }
    let roots: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).filter(|l| !parent_of.contains_key(l)).collect();
    let [root] = roots.as_slice() else {
        return Err(format!("{} root links ({}): not one tree", roots.len(), few(roots.iter().copied())));
    };
    // Every link from the root, parents before children (breadth first, no recursion).
    let mut order: Vec<&str> = vec![root];
    let mut k = 0;
    while k < order.len() {
        order.extend(children.get(order[k]).into_iter().flatten().map(|j| j.child.link.as_str()));
        k += 1;
    }
    if order.len() < links {
        let reached: HashSet<&str> = order.iter().copied().collect();
        let detached = robot.links.iter().map(|l| l.name.as_str()).filter(|l| !reached.contains(l));
        return Err(format!(
            "links {} are not connected to the root link {} (a detached cycle of joints, or a second tree)",
            few(detached),
            few([*root])
        ));
    }
    // Children before parents: whether an actuated joint lies below each link.
    let mut drives = HashSet::new();
    for link in order.iter().rev() {
        if children.get(link).into_iter().flatten().any(|j| actuated(j) || drives.contains(j.child.link.as_str())) {
            drives.insert(*link);
        }
    }
    Ok(Tree { root, children, drives })
}
