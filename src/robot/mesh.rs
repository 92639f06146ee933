//! A URDF's mesh files: where `package://`, `file://` and plain names point, and their vertices
//! (STL, COLLADA and OBJ through the `mesh-loader` crate), in the mesh's frame and metres, scaled
//! as the URDF says.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

/// Largest mesh file read, bytes (the largest ROS-Industrial visual meshes are a few MB).
const MOST_MESH_BYTES: u64 = 256 << 20;

/// Why a mesh cannot be used: the file and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// A `package://` name without a package root to find it under.
    #[error("{filename}: a package:// mesh needs --package-root (the folder holding the package `{package}`)")]
    NoPackageRoot {
        /// The name as the URDF gives it.
        filename: String,
        /// The package it names.
        package: String,
    },
    /// A name calsim does not resolve (another scheme, or an empty path).
    #[error("{filename}: not a package://, file:// or plain path")]
    Unresolvable {
        /// The name as the URDF gives it.
        filename: String,
    },
    /// The file cannot be read or parsed.
    #[error("{path}: {reason}")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        reason: String,
    },
    /// The scale is not three finite non-zero numbers within +-1000.
    #[error("{filename}: scale {scale:?} is not three finite non-zero factors within +-1000")]
    BadScale {
        /// The name as the URDF gives it.
        filename: String,
        /// The scale.
        scale: [f64; 3],
    },
}

/// The file a URDF mesh `filename` names: `package://NAME/PATH` under `package_root/NAME/PATH`,
/// `file:///abs` as it is, any other path relative to the URDF's folder `urdf_dir`.
pub fn resolve(filename: &str, urdf_dir: &Path, package_root: Option<&Path>) -> Result<PathBuf, MeshError> {
    if let Some(rest) = filename.strip_prefix("package://") {
        let (package, path) = rest.split_once('/').unwrap_or((rest, ""));
        if package.is_empty() || path.is_empty() {
            return Err(MeshError::Unresolvable { filename: filename.into() });
        }
        let root = package_root.ok_or_else(|| MeshError::NoPackageRoot { filename: filename.into(), package: package.into() })?;
        return Ok(root.join(package).join(path));
    }
    let path = filename.strip_prefix("file://").unwrap_or(filename);
    if path.is_empty() || path.contains("://") {
        return Err(MeshError::Unresolvable { filename: filename.into() });
    }
    Ok(urdf_dir.join(path))
}

/// The vertices of every mesh in the file at `path`, in its frame, scaled by `scale` (the URDF's
/// factors; the file's own unit is metres, COLLADA's `<unit>` applied).
pub fn vertices(path: &Path, filename: &str, scale: [f64; 3]) -> Result<Vec<Vector3<f64>>, MeshError> {
    if !scale.iter().all(|s| s.is_finite() && *s != 0.0 && s.abs() <= 1e3) {
        return Err(MeshError::BadScale { filename: filename.into(), scale });
    }
    let unreadable = |reason: String| MeshError::Unreadable { path: path.to_path_buf(), reason };
    let bytes = crate::io::read_bytes_at_most(path, MOST_MESH_BYTES).map_err(|e| unreadable(e.to_string()))?;
    // A COLLADA file is XML, read by a parser that recurses once per nested element.
    if crate::io::xml::looks_like_xml(&bytes) {
        crate::io::xml::check_shape_bytes(&bytes).map_err(|e| unreadable(e.to_string()))?;
    }
    // The reader reads nothing else (a COLLADA or OBJ file that names others gets an error).
    let loader = mesh_loader::Loader::default().custom_reader(|p| Err(std::io::Error::other(format!("{} not read", p.display()))));
    let scene = loader.load_from_slice(&bytes, path).map_err(|e| unreadable(e.to_string()))?;
    let out: Vec<Vector3<f64>> = scene
        .meshes
        .iter()
        .flat_map(|m| m.vertices.iter())
        .map(|v| Vector3::new(f64::from(v[0]) * scale[0], f64::from(v[1]) * scale[1], f64::from(v[2]) * scale[2]))
        .collect();
    if out.is_empty() {
        return Err(unreadable("no vertices".into()));
    }
    if let Some(v) = out.iter().find(|v| !v.iter().all(|x| x.is_finite() && x.abs() <= 100.0)) {
        return Err(unreadable(format!("vertex {:?} m: finite numbers within +-100 m", v.as_slice())));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::{MeshError, resolve};

    /// `package://` names resolve under the package root, plain and `file://` names beside the
    /// URDF or as given; a package:// name without a root is an error naming the package.
    #[test]
    fn mesh_names_resolve_against_the_package_root() {
        let urdf = Path::new("/u");
        let root = Path::new("/r");
        assert_eq!(resolve("package://pkg/meshes/a.stl", urdf, Some(root)).unwrap(), Path::new("/r/pkg/meshes/a.stl"));
        assert_eq!(resolve("meshes/a.stl", urdf, None).unwrap(), Path::new("/u/meshes/a.stl"));
        assert_eq!(resolve("file:///m/a.stl", urdf, None).unwrap(), Path::new("/m/a.stl"));
        assert!(matches!(resolve("package://pkg/a.stl", urdf, None), Err(MeshError::NoPackageRoot { package, .. }) if package == "pkg"));
        assert!(matches!(resolve("http://x/a.stl", urdf, None), Err(MeshError::Unresolvable { .. })));
        assert!(matches!(resolve("package://pkg", urdf, Some(root)), Err(MeshError::Unresolvable { .. })));
    }
}
