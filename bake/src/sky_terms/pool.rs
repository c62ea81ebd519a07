//! Pooling a near group's sky views and shrinking the pooled terms by their noise
//! (`super`'s module docs: why, and what chose each constant).

use super::{SHRINK, SHRINK_DARKER, UNCERTAIN};

/// What [`super::sky_terms`] traced at a surfel: its view of the sky `v`, the baselines its group
/// may be pooled against ([`pooled`]: the probes' sky through its near field, the control
/// variate's integral `A(n) . T`, and none), the variance of `v` (floored), and its weight in
/// the group (its hits; 0 for a surfel not traced).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Traced {
    pub(super) view: f32,
    pub(super) baselines: [f32; 3],
    pub(super) variance: f32,
    pub(super) weight: f32,
}

/// Per surfel, its term before shrinking (`v - probes`, `v` pooled over the traced surfels of
/// its near group, weighted by their hits) and the variance of the pooled mean.
///
/// What is pooled is `v` less a baseline known exactly at each surfel, the one that leaves the
/// group most uniform: `v - baseline` is averaged and each surfel adds its own baseline back.
/// The rays' noise is the same whichever baseline is taken off, so the one whose differences
/// spread least across the group is the one the sky varies least against. Where the probes'
/// sky falls off across a gallery wall that sees none (atrium_13: 0.2% to 2.5% within one
/// group of 16), `v` itself is uniform and the difference to the probes is not: pooling the
/// difference gave each surfel the group's mean correction, about half its own, and left 3 of
/// its 4 leaking points (1 at 64 rays with the baseline chosen, 8.31% -> 7.99%,
/// docs/results/surface_sky_pool.md). Where a skylight's edge crosses the group the probes
/// follow it and the difference is the uniform one (cave_7, `super`'s module docs). The
/// choice is made on the same noisy `v` it pools, clamped to [0, 1]: in a group that sees no
/// sky, or all of it, the clamp makes `v` look uniform and "none" tends to win, which is the
/// right baseline there.
pub(super) fn pooled(groups: &[[u32; 2]], traced: &[Traced]) -> Vec<(f32, f32)> {
    let mut out: Vec<(f32, f32)> = traced
        .iter()
        .map(|t| (t.view - t.baselines[0], t.variance))
        .collect();
    for &[first, count] in groups {
        let range = first as usize..(first + count) as usize;
        let members: Vec<(usize, f64)> = (range.clone())
            .map(|s| (s, f64::from(traced[s].weight)))
            .filter(|m| m.1 > 0.0)
            .collect();
        let weight: f64 = members.iter().map(|m| m.1).sum();
        if weight <= 0.0 {
            continue;
        }
        let x = |s: usize, b: usize| f64::from(traced[s].view - traced[s].baselines[b]);
        let means =
            [0, 1, 2].map(|b| members.iter().map(|&(s, w)| w * x(s, b)).sum::<f64>() / weight);
        let spreads = [0, 1, 2].map(|b| {
            (members.iter())
                .map(|&(s, w)| w * (x(s, b) - means[b]).powi(2))
                .sum::<f64>()
        });
        // The first of the least spread: the probes' baseline where they tie.
        let best = (1..3).fold(
            0,
            |best, b| if spreads[b] < spreads[best] { b } else { best },
        );
        let m = means[best];
        let variance = members
            .iter()
            .map(|&(s, w)| w * w * f64::from(traced[s].variance))
            .sum::<f64>()
            / (weight * weight);
        for s in range {
            let t = &traced[s];
            let own = f64::from(t.baselines[best]) + m - f64::from(t.baselines[0]);
            out[s] = (own as f32, variance as f32);
        }
    }
    out
}

/// The surfels of every near group of `groups` in which a traced surfel's pooled term
/// (`terms`: [`pooled`]'s term and variance) is uncertain ([`UNCERTAIN`]), in surfel order.
/// `shares` holds, per traced surfel, the larger of the sky it sees and its probes bring it
/// (`None`: not traced).
pub(super) fn uncertain_surfels(
    groups: &[[u32; 2]],
    shares: &[Option<f32>],
    terms: &[(f32, f32)],
) -> Vec<usize> {
    let uncertain = |s: usize| {
        shares[s].is_some_and(|share| {
            let (d, variance) = terms[s];
            let cut = shrinkage(d, variance);
            d.abs() > cut && cut >= UNCERTAIN * share
        })
    };
    (groups.iter())
        .map(|&[first, count]| first as usize..(first + count) as usize)
        .filter(|range| range.clone().any(uncertain))
        .flatten()
        .collect()
}

/// What the shrink takes off a pooled term `d` of noise `variance` (all of it, if less):
/// [`SHRINK`] standard deviations, [`SHRINK_DARKER`] where it darkens its surfel.
fn shrinkage(d: f32, variance: f32) -> f32 {
    let k = if d < 0.0 { SHRINK_DARKER } else { SHRINK };
    k * variance.sqrt()
}

/// Pooled term `d` of noise `variance` shrunk toward 0 (soft threshold) by [`SHRINK`] standard
/// deviations, by [`SHRINK_DARKER`] where it darkens its surfel.
pub(super) fn shrunk(d: f32, variance: f32) -> f32 {
    d.signum() * (d.abs() - shrinkage(d, variance)).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A term that darkens its surfel loses half a standard deviation, one that brightens a
    /// whole one, and either is dropped under that.
    #[test]
    fn a_darkening_term_is_shrunk_less() {
        let variance = 0.01f32 * 0.01;
        let cases = [
            (-0.03, -0.025),
            (0.03, 0.02),
            (-0.004, 0.0),
            (0.008, 0.0),
            (0.0, 0.0),
        ];
        for (d, want) in cases {
            assert!(
                (shrunk(d, variance) - want).abs() < 1e-7,
                "{d}: {}",
                shrunk(d, variance)
            );
        }
    }

    /// A group is traced again where a traced surfel's term loses at least a tenth of its sky
    /// to the shrink and keeps some of it: a dark surfel whose probes bring it a ray's worth
    /// of sky (cave_139 of stop 65's blind levels). Not where the shrink takes a sliver of a
    /// sure term, nor where it takes all of a term within its noise, nor an untraced surfel.
    #[test]
    fn an_uncertain_group_is_traced_again() {
        let groups = [[0, 2], [2, 2], [4, 1], [5, 1]];
        // Surfel 1 alone would be sure (its share is large): its group goes for surfel 0's sake.
        let shares = [
            Some(0.0036),
            Some(0.5),
            Some(0.5),
            Some(0.5),
            Some(0.002),
            None,
        ];
        let sd = 0.0039f32;
        let terms = [
            (-0.0036, sd * sd),
            (-0.0036, sd * sd),
            (0.05, 1e-6),
            (0.05, 1e-6),
            (0.001, 1e-4),
            (-0.5, 1e-4),
        ];
        assert_eq!(uncertain_surfels(&groups, &shares, &terms), vec![0, 1]);
    }

    /// A traced surfel of weight 1 that sees `view` of the sky, its probes `probes`, its
    /// control variate's integral `cosine`, and no noise.
    fn surfel(view: f32, probes: f32, cosine: f32) -> Traced {
        Traced {
            view,
            baselines: [probes, cosine, 0.0],
            variance: 0.0,
            weight: 1.0,
        }
    }

    #[test]
    fn a_group_that_sees_no_sky_takes_off_each_surfels_own_probes() {
        // A gallery wall under probes whose sky falls off across it: the difference to the
        // probes varies, the view does not. Each surfel's term is minus its own probes' sky,
        // not the group's mean difference.
        let traced: Vec<Traced> = [0.025, 0.017, 0.009, 0.002]
            .iter()
            .map(|&p| surfel(0.0, p, p))
            .collect();
        let terms = pooled(&[[0, 4]], &traced);
        for (t, s) in terms.iter().zip(&traced) {
            assert!((t.0 + s.baselines[0]).abs() < 1e-7, "{t:?} for {s:?}");
        }
    }

    #[test]
    fn a_view_that_follows_the_probes_pools_the_difference() {
        // A skylight's edge across the group: the view falls off as the probes' sky does,
        // 0.1 under it. Every surfel gets the group's difference, and the untraced one
        // (weight 0) takes no part.
        let mut traced: Vec<Traced> = [0.5, 0.3, 0.2, 0.1]
            .iter()
            .map(|&p| surfel(p - 0.1, p, 0.4))
            .collect();
        traced.push(Traced {
            view: 1.0,
            ..Traced::default()
        });
        let terms = pooled(&[[0, 5]], &traced);
        for t in &terms[..4] {
            assert!((t.0 + 0.1).abs() < 1e-6, "{t:?}");
        }
    }

    #[test]
    fn a_view_that_follows_the_cosine_integral_pools_against_it() {
        // The view tracks the control variate's integral while the probes' sky (through the
        // near field) does not: each surfel keeps its own integral less a common 0.05.
        let traced: Vec<Traced> = [(0.4, 0.1), (0.3, 0.3), (0.2, 0.0), (0.1, 0.2)]
            .iter()
            .map(|&(cosine, probes)| surfel(cosine - 0.05, probes, cosine))
            .collect();
        let terms = pooled(&[[0, 4]], &traced);
        for (t, s) in terms.iter().zip(&traced) {
            let want = s.view - s.baselines[0];
            assert!((t.0 - want).abs() < 1e-6, "{t:?} for {s:?}");
        }
    }

    #[test]
    fn an_untraced_surfel_takes_no_part_and_a_group_of_none_stays_zero() {
        let mut traced = vec![surfel(0.0, 0.1, 0.1), surfel(0.2, 0.1, 0.1)];
        // Untraced (weight 0) with a view that would pull the mean.
        traced.push(Traced {
            view: 1.0,
            ..Traced::default()
        });
        let terms = pooled(&[[0, 3]], &traced);
        assert!((terms[0].0 - 0.0).abs() < 1e-6, "{:?}", terms[0]);
        let none = pooled(&[[0, 2]], &[Traced::default(); 2]);
        assert_eq!(none, vec![(0.0, 0.0); 2]);
    }

    #[test]
    fn the_pooled_variance_is_that_of_the_weighted_mean() {
        let mut traced = vec![surfel(0.0, 0.1, 0.1), surfel(0.0, 0.1, 0.1)];
        traced[0].variance = 4e-4;
        traced[1].variance = 4e-4;
        traced[1].weight = 3.0;
        let terms = pooled(&[[0, 2]], &traced);
        // (1 * 4e-4 + 9 * 4e-4) / 16
        assert!((terms[0].1 - 2.5e-4).abs() < 1e-9, "{:?}", terms[0]);
        assert_eq!(terms[0].1, terms[1].1);
    }
}
