"""The demo fixture: Spot smoothed by Open3D's Taubin filter, a stand-in "reconstruction" that the
README's run command evaluates against the original Spot."""

import pathlib

import open3d as o3d

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "fixtures" / "data"


def main():
    mesh = o3d.io.read_triangle_mesh(str(DATA / "spot_triangulated.obj"))
    # Open3D splits vertices at uv seams; weld them so smoothing does not open cracks.
    mesh = mesh.merge_close_vertices(1e-9)
    mesh.triangle_uvs = o3d.utility.Vector2dVector()
    smooth = mesh.filter_smooth_taubin(number_of_iterations=10)
    smooth.compute_vertex_normals()
    out = DATA / "spot_taubin.ply"
    o3d.io.write_triangle_mesh(str(out), smooth, write_ascii=False, write_vertex_colors=False,
                               write_triangle_uvs=False)
    print(f"wrote {out} ({len(smooth.vertices)} vertices, {len(smooth.triangles)} triangles)")


if __name__ == "__main__":
    main()
