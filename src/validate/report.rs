//! What a validation found: per-mesh figures and the issues, and how the report reads.

use std::fmt;
use std::path::PathBuf;

use crate::mesh::Bounds;

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    Warning,
    Error,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    pub severity: Severity,
    /// Where: "mesh 'tree' primitive 1 triangle 17", "node 3 'scatter'", "line 12", …
    pub location: String,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PrimitiveReport {
    pub vertices: usize,
    pub triangles: usize,
    /// Points drawn (POINTS primitives, e.g. point leaves).
    pub points: usize,
    pub bounds: Option<Bounds>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MeshReport {
    pub name: String,
    pub primitives: Vec<PrimitiveReport>,
    /// Bounds in metres as the first (unrotated) node holding the mesh places it, where that node
    /// scales or moves it: a quantized mesh's positions are integers (KHR_mesh_quantization).
    pub placed: Option<Bounds>,
}

impl MeshReport {
    pub fn vertices(&self) -> usize {
        self.primitives.iter().map(|p| p.vertices).sum()
    }
    pub fn triangles(&self) -> usize {
        self.primitives.iter().map(|p| p.triangles).sum()
    }
    pub fn points(&self) -> usize {
        self.primitives.iter().map(|p| p.points).sum()
    }
    pub fn bounds(&self) -> Option<Bounds> {
        let corners: Vec<[f32; 3]> =
            self.primitives.iter().filter_map(|p| p.bounds).flat_map(|b| [b.min, b.max]).collect();
        Bounds::of(&corners)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct ValidationReport {
    pub path: PathBuf,
    pub meshes: Vec<MeshReport>,
    pub issues: Vec<Issue>,
}

impl ValidationReport {
    /// No error-level issue.
    pub fn ok(&self) -> bool {
        self.errors() == 0
    }
    pub fn errors(&self) -> usize {
        self.issues.iter().filter(|i| i.severity == Severity::Error).count()
    }
    pub fn warnings(&self) -> usize {
        self.issues.iter().filter(|i| i.severity == Severity::Warning).count()
    }
}

impl fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v: usize = self.meshes.iter().map(MeshReport::vertices).sum();
        let t: usize = self.meshes.iter().map(MeshReport::triangles).sum();
        writeln!(f, "{}: {} meshes, {v} vertices, {t} triangles", self.path.display(), self.meshes.len())?;
        for m in &self.meshes {
            write!(f, "  mesh {:?}: {} vertices, {} triangles", m.name, m.vertices(), m.triangles())?;
            if m.points() > 0 {
                write!(f, ", {} points", m.points())?;
            }
            match (m.bounds(), m.placed) {
                (Some(b), Some(p)) => writeln!(
                    f,
                    ", bounds {:?} .. {:?} as stored, {:?} .. {:?} as placed by its node",
                    b.min, b.max, p.min, p.max
                )?,
                (Some(b), None) => writeln!(f, ", bounds {:?} .. {:?}", b.min, b.max)?,
                _ => writeln!(f)?,
            }
        }
        for i in &self.issues {
            let sev = match i.severity {
                Severity::Error => "error",
                Severity::Warning => "warning",
            };
            writeln!(f, "  {sev}: {}: {}", i.location, i.message)?;
        }
        if self.ok() {
            write!(f, "ok ({} warnings)", self.warnings())
        } else {
            write!(f, "FAILED: {} errors, {} warnings", self.errors(), self.warnings())
        }
    }
}

pub(super) fn issue(severity: Severity, location: impl Into<String>, message: impl Into<String>) -> Issue {
    Issue { severity, location: location.into(), message: message.into() }
}
