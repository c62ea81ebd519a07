// Any-hit shadow rays through the asset's BVH2: the plain stack traversal, slab test and
// Moller-Trumbore intersection of prt_runtime::shadow_rays, operation for operation. A scene
// without triangles is uploaded as one leaf holding a degenerate (all-zero) triangle, which no
// ray hits.

@group(1) @binding(0) var<storage, read> bvh_nodes: array<BvhNode>;
@group(1) @binding(1) var<storage, read> triangles: array<Triangle>;

fn safe_inverse(x: f32) -> f32 {
    if abs(x) < 1e-20 {
        return select(1e20, -1e20, x < 0.0);
    }
    return 1.0 / x;
}

fn hits_box(node: BvhNode, o: vec3<f32>, inv: vec3<f32>, tmax: f32) -> bool {
    let t0 = (node.bmin - o) * inv;
    let t1 = (node.bmax - o) * inv;
    let lo = min(t0, t1);
    let hi = max(t0, t1);
    let near = max(max(max(lo.x, lo.y), lo.z), 0.0);
    let far = min(min(min(hi.x, hi.y), hi.z), tmax);
    return near <= far;
}

fn intersect_triangle(t: Triangle, o: vec3<f32>, d: vec3<f32>, tmax: f32) -> bool {
    let e1 = t.v1 - t.v0;
    let e2 = t.v2 - t.v0;
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return false;
    }
    let inv_det = 1.0 / det;
    let s = o - t.v0;
    // Barycentric tests widened by EDGE_TOLERANCE (prt_format): no ray slips through a shared edge.
    let u = dot(s, p) * inv_det;
    if u < -EDGE_TOLERANCE || u > 1.0 + EDGE_TOLERANCE {
        return false;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv_det;
    if v < -EDGE_TOLERANCE || u + v > 1.0 + EDGE_TOLERANCE {
        return false;
    }
    let dist = dot(e2, q) * inv_det;
    return dist > 0.0 && dist < tmax;
}

fn occluded(o: vec3<f32>, d: vec3<f32>, tmax: f32) -> bool {
    let inv = vec3<f32>(safe_inverse(d.x), safe_inverse(d.y), safe_inverse(d.z));
    var stack: array<u32, BVH_STACK>;
    var top = 1u;
    stack[0] = 0u;
    while top > 0u {
        top = top - 1u;
        let node = bvh_nodes[stack[top]];
        if !hits_box(node, o, inv, tmax) {
            continue;
        }
        if node.count > 0u {
            for (var i = node.first; i < node.first + node.count; i = i + 1u) {
                if intersect_triangle(triangles[i], o, d, tmax) {
                    return true;
                }
            }
        } else if top + 2u <= BVH_STACK {
            stack[top] = node.first;
            stack[top + 1u] = node.first + 1u;
            top = top + 2u;
        }
    }
    return false;
}

// Twin of prt_runtime::shadow_rays::ray_offset: `scale` is the scene's length scale.
fn ray_offset(p: vec3<f32>, scale: f32) -> f32 {
    let a = abs(p);
    return max(RAY_OFFSET_MAGNITUDE * max(max(a.x, a.y), a.z), RAY_OFFSET_SCALE * scale);
}
