"""XDMF 3 text for a shard: a temporal collection over load steps that opens in ParaView.

Heavy data stay in the HDF5 files; the XDMF file only points into them (the mesh into the shared
geometry file, displacements into the shard), so it costs a few kilobytes per simulation.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr


def _item(dims: tuple[int, ...], number_type: str, precision: int, ref: str) -> str:
    d = " ".join(str(x) for x in dims)
    return (f'<DataItem Dimensions="{d}" NumberType="{number_type}" Precision="{precision}" '
            f'Format="HDF">{ref}</DataItem>')


def shard_xdmf(*, shard_file: str, geometry_file: str, n_nodes: int, n_cells: int,
               n_out: int, output_is_all: bool, fractions: list[float], name: str) -> str:
    """XDMF for one shard.

    Args:
        shard_file: the shard's HDF5 file name, relative to the XDMF file.
        geometry_file: the geometry HDF5 file, relative to the XDMF file.
        n_nodes: number of mesh nodes.
        n_cells: number of tetrahedra.
        n_out: number of output nodes.
        output_is_all: displacement covers every node (else a point cloud of the output nodes,
            whose coordinates the shard stores under /xdmf/points).
        fractions: load fraction of each stored step (the XDMF time values).
        name: grid name shown in ParaView.
    """
    if output_is_all:
        topo = (f'<Topology TopologyType="Tetrahedron" NumberOfElements="{n_cells}">'
                + _item((n_cells, 4), "Int", 8, f"{geometry_file}:/cells") + "</Topology>")
        geom = ('<Geometry GeometryType="XYZ">'
                + _item((n_nodes, 3), "Float", 8, f"{geometry_file}:/points") + "</Geometry>")
    else:
        topo = f'<Topology TopologyType="Polyvertex" NumberOfElements="{n_out}"/>'
        geom = ('<Geometry GeometryType="XYZ">'
                + _item((n_out, 3), "Float", 8, f"{shard_file}:/xdmf/points") + "</Geometry>")
    steps = []
    n_steps = len(fractions)
    full = _item((n_steps, n_out, 3), "Float", 8, f"{shard_file}:/displacement")
    for i, t in enumerate(fractions):
        # A hyperslab (start, stride, count) selects step i of /displacement without a copy.
        disp = (f'<DataItem ItemType="HyperSlab" Dimensions="{n_out} 3">'
                f'<DataItem Dimensions="3 3" Format="XML">{i} 0 0 1 1 1 1 {n_out} 3</DataItem>'
                f"{full}</DataItem>")
        steps.append(
            f'   <Grid Name="step_{i:03d}" GridType="Uniform">\n'
            f'    <Time Value="{t!r}"/>\n    {topo}\n    {geom}\n'
            f'    <Attribute Name="displacement_mm" AttributeType="Vector" Center="Node">'
            f"{disp}</Attribute>\n   </Grid>")
    body = "\n".join(steps)
    return ('<?xml version="1.0"?>\n<Xdmf Version="3.0">\n <Domain>\n'
            f'  <Grid Name={quoteattr(name)} GridType="Collection" CollectionType="Temporal">\n'
            f"{body}\n  </Grid>\n </Domain>\n</Xdmf>\n")
