"""Pinhole frames by rasterizing: the same per-pixel hits as the ray cast, without casting rays.

For a pinhole camera every pixel ray starts at the camera centre, so whether the ray of pixel
(u, v) crosses a triangle is decided by three planes through the centre and the triangle's
edges: with camera-frame corners ``p0, p1, p2`` and the pixel ray ``d = ((u - cx) / fx,
(v - cy) / fy, 1)``, the ray hits the triangle in front of the camera exactly when the three
triple products ``d . (p1 x p2)``, ``d . (p2 x p0)``, ``d . (p0 x p1)`` share the sign of
``det = p0 . ((p1 - p0) x (p2 - p0))``. Their shares of the sum are the hit's barycentric
coordinates, and ``det / (d . n)`` with ``n = (p1 - p0) x (p2 - p0)`` its z-depth: the ray
parameter of the exact pixel ray, as the ray caster reports it. Nothing is interpolated in screen
space, so triangles that cross the camera plane need no geometric clipping (points behind the
camera fail the sign test), and the depth is that of the ray-plane intersection in float64.

A frame is made in these passes:

0. culling (small frames, drawn in one thread): triangles are grouped in clusters of
   ``CLUSTER_FACES`` neighbours (Z-order of their centroids) with a bounding sphere each, and
   a cluster whose sphere lies wholly outside a side of the view volume is skipped, vertices
   and triangles: every corner of its triangles would get that side's outcode bit, so the
   frame is the same (only a share of a room is in view of a 90-degree camera, and the passes
   below cost per vertex and per triangle); within a cluster seen, each group of
   ``SUBCLUSTER_FACES`` is tested alike before its triangles are set up;
1. vertices (split between the threads; small frames: all of them in vectorized loops, or
   those of the clusters in view one at a time when they are under a quarter): the
   camera-frame position, the image position and an outcode per vertex, one bit per side of
   the view volume it lies outside of;
2. setup (triangles split between the threads): triangles whose corners share an outcode bit
   (behind the camera, outside the image, entirely beyond the depth range) are dropped, and
   so are back faces of closed solids the camera is outside of (a front face of the same
   solid is always nearer); the others take their corners' camera-frame positions (float64)
   from pass 1 and from them get their edge planes, inverse-depth plane and barycentric
   planes, all in pixel units, and the image rows they can cover (corners clipped to
   ``z >= NEAR_PLANE_M`` and projected), packed into a list;
3. binning: which packed triangles touch each band of ``BAND_ROWS`` image rows (a small
   frame drawn in one thread is one band, ``SINGLE_BAND_MAX_BYTES``);
4. drawing (bands dealt out to the threads in turn): per row of a triangle, the span of
   columns where all three edge planes are non-negative (a bound per edge, from its plane),
   each pixel of it kept when its inverse depth beats the band's z-buffer; then, per pixel of
   the band, the winner's z-depth (as float32, with the range cut), triangle id and
   barycentric (u, v), or depth 0 and id -1.

The kernels release the GIL and run in a small pool of Python threads, not numba's threading
layer, which would have to coexist with torch's and with spawned env workers. Triangles share
edge planes exactly (the cross product of two corners only changes sign when they swap), so a
ray through a shared edge is claimed by both neighbours and the image has no cracks; which of
the two wins such an exact tie can differ from Embree.

Modules: :mod:`.culling` (the per-mesh clusters and closed solids that passes 0 and 2 cull
with), :mod:`.kernels` (the compiled passes 0 to 4) and :mod:`.rasterizer`
(:class:`PinholeRasterizer`, which owns a mesh's data and scratch space and hands the passes
to the threads).
"""

from naruto_gym.sensors.raster.rasterizer import MeshClusters, PinholeRasterizer

__all__ = ["MeshClusters", "PinholeRasterizer"]
