//! Settings the CPU reference and the GPU runtime share: how many light bounces, and how the
//! engine looks the volume up ([`LookupSettings`]; bounces beyond the first sample the volume
//! at every surfel through that lookup). The GPU runtime's own options (volume format, chunk
//! sizes, light and cache capacities) are [`crate::gpu::RuntimeSettings`], which holds these.

/// Most bounces a relight computes: each adds at most the albedo (below 1) times the previous
/// one, so after 100 bounces of albedo 0.9 the next would add 3e-5 of the first.
pub const MAX_BOUNCES: u32 = 100;

/// Light bounces of the GPU runtime. Bounces beyond the first feed the volume back into the
/// surfels, as the prior art does (DDGI, Majercik et al. 2019; Lumen's radiance cache): each
/// pass of the gather over the probes (a *cycle*: one update, or `probes / budget` amortised
/// updates) starts by sampling the volume at every surfel with the engine's own lookup
/// ([`LookupSettings`]) and adding albedo / pi times that irradiance to the surfel's radiance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bounces {
    /// Exactly this many bounces (1: direct light at surfels only, the one-bounce contract).
    /// After a change of lights or sky the bounce light starts again from zero and one cycle
    /// adds one bounce: `n` cycles after the change the volume equals
    /// [`crate::CpuRelighter::relight_with`] with `n` bounces, and the runtime goes idle.
    Fixed(u32),
    /// Bounces without end: every cycle feeds the volume back, never idle, and a change of
    /// lights carries the old bounce light over instead of restarting (no dip in indirect
    /// light). The fed-back light is multiplied by `damping` in (0, 1]: 1 converges to the
    /// full multi-bounce solution (a furnace of albedo a to e / (1 - a), geometrically, since
    /// albedo < 1); lower values settle faster and stay further below it (e / (1 - d a)).
    Feedback { damping: f32 },
}

impl Bounces {
    /// Whether any bounce beyond the first is computed.
    pub fn feeds_back(self) -> bool {
        !matches!(self, Bounces::Fixed(0 | 1))
    }

    /// `Fixed(1..=MAX_BOUNCES)`, or `Feedback` with a damping in (0, 1].
    pub fn is_valid(self) -> bool {
        match self {
            Bounces::Fixed(n) => (1..=MAX_BOUNCES).contains(&n),
            Bounces::Feedback { damping } => damping > 0.0 && damping <= 1.0,
        }
    }
}

/// How the engine-side snippet (`sample_irradiance`) and its CPU twin
/// ([`crate::surface::SurfaceSampler`], over [`crate::sample::VolumeSampler`]) look the probe
/// volume up at a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LookupSettings {
    /// How far the probe volume's lookup (points without a surfel's terms, and the surface
    /// lookup's fallback where a surfel sees none of its probes) moves a point along its
    /// normal before sampling, in probe spacings (relative to the scene, so one value suits every grid;
    /// `PrtRuntime::volume_info` turns it into metres). Probes just behind a surface see its
    /// back faces: they are invalid or dark, and a point sampled on the surface still gives
    /// them trilinear weight (self-shadowing, and light leaking through thin walls from probes
    /// on the other side). A larger bias weights the probes in front of the surface more, at
    /// the price of sampling the lighting off the surface (contact detail blurs, and a bias
    /// beyond the wall's distance to the next probe can reach past nearby geometry). 0 samples
    /// exactly at the point. Default 0.2: with depth moments it also moves a point on the dark
    /// side of a thin wall far enough past the wall, as the lit side's probes see it, for the
    /// Chebyshev test to reject them (`prt-bench surface`: Sponza at 1.2 m, 12 of 300 points
    /// leaking at 0.2 against 16 at 0.1, mean error 16.3% against 19.4%; the Cornell room
    /// 4.05% against 3.7%).
    pub normal_bias: f32,
    /// The normal bias of the surface lookup ([`crate::surface`]: points with a surfel's
    /// terms), in probe spacings. There the surfel's mask of the probes it sees decides which
    /// probes count, so the bias no longer has to carry a point past a wall and only moves
    /// the point off the lighting it is sampled for. Default 0.1 (stop 69, `prt-bench surface
    /// --lookup default`, against 0.2, the volume's): tuning seeds' median / worst level 5.55 /
    /// 7.27% -> 5.31 / 7.19%, held-out 5.12 / 7.23% -> 4.83 / 7.01%, the bundled Cornell room,
    /// two rooms and thick walls 2.81 / 3.90 / 2.57% -> 2.57 / 3.59 / 2.31%; Sponza under the
    /// sun 14.47% -> 14.49% (11.43% -> 11.83% at half the spacing, 3 -> 5 of 284 leaking there),
    /// with its 31 lights 10.44% -> 10.71% (docs/results/surface_stop69.md). The fallback
    /// where a surfel sees none of its probes keeps `normal_bias`.
    /// The default is `prt_format::surface::SURFACE_BIAS`, where the bake interpolates the
    /// probes' sky for the sky terms.
    pub surface_bias: f32,
    /// The surface lookup's floor under L2's ringing ([`crate::surface::floor_ringing`]): a
    /// point with a surfel whose irradiance `E` reads, before its sky term, under half of `F`
    /// (this share of the non-linear L1 model's irradiance of its probes,
    /// `prt_format::sh::irradiance_l1_nonlinear`, times the share of its near-field rays that
    /// escape) reads `F - E` instead: `F` where L2 reads 0. A dark room's probes that see the
    /// lit room through its door ring L2 below 0 behind that lobe, and points on the door's
    /// wall read 0 (stop 69's blind interior_220). Default 0.15 (stop 70, `prt-bench surface
    /// --ringing-floor`, docs/results/surface_stop70.md; the fade since stop 71,
    /// docs/results/surface_stop71.md); 0: off.
    pub ringing_floor: f32,
    /// Weight each probe by DDGI's Chebyshev test against its depth moments (the mean and
    /// deviation of its hit distances per direction, `prt_format::depth`; see
    /// `shaders/sample_irradiance.wgsl`): no light through walls from probes on their far side,
    /// for 56 texel loads and 8 depth words per lookup instead of 7 filtered fetches. Off:
    /// hardware trilinear over the probes' weights only.
    pub depth_moments: bool,
    /// Where the asset has surface terms for the point (`prt_format::surface`), weight the
    /// probes by which ones the point's surfel sees and scale by its near field (bake-time
    /// rays; [`crate::surface`]). Held-out levels of the family at the default bake: median
    /// level 6.8% against 8.9%, worst 9.0% against 19.8%, over-lit pixels at most 1.3% against
    /// 3.8% (`docs/results/surface.md`). Off, or an asset without terms: the probe volume
    /// alone.
    pub surface_terms: bool,
    /// Where the point has a surfel, swap the sky its probes bring it for the sky it sees
    /// itself: add its sky term (`prt_format::surface::sky_term`, format 14) times pi times the
    /// sky's mean radiance ([`crate::surface`]). Off, or an asset without terms: the probes'
    /// view of the sky.
    pub sky_terms: bool,
}

impl Default for LookupSettings {
    fn default() -> Self {
        LookupSettings {
            normal_bias: 0.2,
            surface_bias: prt_format::surface::SURFACE_BIAS,
            ringing_floor: 0.15,
            depth_moments: true,
            surface_terms: true,
            sky_terms: true,
        }
    }
}
