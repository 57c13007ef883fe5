//! Per-scene material tables for the GPU: each material's [`BrdfTable`] for the sensor's
//! bistatic angle, packed with [`GpuTables::pack`], built once per angle and cached.

use super::gpu::{GpuTables, PartRef};
use crate::brdf::table::{BrdfTable, BrdfTableOptions, TableFrame};
use crate::brdf::Material;
use crate::error::Result;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

type Cached = (Arc<GpuTables>, Arc<Vec<BrdfTable>>);

/// The materials of a scene and their packed tables by bistatic angle and table options.
pub struct SceneTables {
    pub materials: Vec<Arc<Material>>,
    cache: Mutex<HashMap<(u64, String), Cached>>,
}

impl SceneTables {
    pub fn new(materials: Vec<Arc<Material>>) -> Self {
        SceneTables {
            materials,
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// The packed tables for `beta` with the default grids (built on first use); `true`
    /// if built by this call.
    pub fn get(&self, beta: f64) -> Result<(Arc<GpuTables>, bool)> {
        self.get_with(beta, &BrdfTableOptions::default())
    }

    /// As [`SceneTables::get`] with table options (`frame` is always the bisector frame,
    /// which the kernel reads).
    pub fn get_with(&self, beta: f64, opts: &BrdfTableOptions) -> Result<(Arc<GpuTables>, bool)> {
        let (g, _, built) = self.get_with_tables(beta, opts)?;
        Ok((g, built))
    }

    /// As [`SceneTables::get_with`], with the f64 tables (for the CPU twin).
    pub fn get_with_tables(
        &self,
        beta: f64,
        opts: &BrdfTableOptions,
    ) -> Result<(Arc<GpuTables>, Arc<Vec<BrdfTable>>, bool)> {
        let opts = BrdfTableOptions {
            frame: Some(TableFrame::Bisector),
            ..*opts
        };
        let key = (beta.to_bits(), format!("{opts:?}"));
        if let Some((g, t)) = self
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return Ok((g.clone(), t.clone(), false));
        }
        let tables: Vec<BrdfTable> = self
            .materials
            .par_iter()
            .map(|m| BrdfTable::build(m, beta, &opts))
            .collect::<Result<_>>()?;
        let refs: Vec<Vec<PartRef<'_>>> = tables.iter().map(PartRef::of).collect();
        let g = Arc::new(GpuTables::pack(&refs, beta)?);
        let t = Arc::new(tables);
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, (g.clone(), t.clone()));
        Ok((g, t, true))
    }
}
