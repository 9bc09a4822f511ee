// Benchmark helper (cost that follows the smoke): the same cache in a larger box. `vdbturb_bench_pad IN OUT N`
// copies IN to OUT with the domain grown to N^3 voxels from index 0: Blender's file_base_resolution becomes N
// (its domain, a sparse cache as Mantaflow writes one), and a velocity grid without it gets active zero tiles
// over the box (a Houdini container whose velocity covers the whole box). The smoke and its voxels are untouched.
#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>

#include <cstdlib>
#include <iostream>

int main(int argc, char** argv)
{
    if (argc != 4) {
        std::cerr << "usage: vdbturb_bench_pad IN OUT N\n";
        return 2;
    }
    openvdb::initialize();
    const int n = std::atoi(argv[3]);
    openvdb::io::File in(argv[1]);
    in.open();
    openvdb::GridPtrVecPtr grids = in.getGrids();
    openvdb::MetaMap::Ptr meta = in.getMetadata();
    in.close();
    const openvdb::CoordBBox box(openvdb::Coord(0), openvdb::Coord(n - 1));
    for (auto& g : *grids) {
        if (g->getMetadata<openvdb::Vec3IMetadata>("file_base_resolution")) {
            g->insertMeta("file_base_resolution", openvdb::Vec3IMetadata(openvdb::Vec3i(n, n, n)));
            continue;
        }
        auto v = openvdb::gridPtrCast<openvdb::Vec3SGrid>(g);
        if (!v) continue;
        auto padded = openvdb::Vec3STree::Ptr(new openvdb::Vec3STree(v->tree().background()));
        padded->fill(box, openvdb::Vec3s(0.0f), true);
        openvdb::tree::ValueAccessor<openvdb::Vec3STree> acc(*padded);
        for (auto it = v->tree().cbeginValueOn(); it; ++it)
            if (it.isVoxelValue()) acc.setValue(it.getCoord(), *it);
        v->setTree(padded);
    }
    openvdb::io::File out(argv[2]);
    out.write(*grids, *meta);
    out.close();
    return 0;
}
