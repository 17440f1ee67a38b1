"""``gpr3d dataset``: pack a simulated dataset into one file, or export a packed one as COCO."""

from __future__ import annotations

from gpr3d.cli._common import _check_suffix, _out_folder

NAME = "dataset"
HELP = "pack a simulated dataset into one file, or export a packed one as COCO"
EPILOG = ("examples:\n  gpr3d dataset pack gprmax400 datasets/gprmax400.h5\n"
             "  gpr3d dataset export datasets/gprmax400.h5 coco_out\n"
             "  gpr3d dataset preview gprmax400 labels.png --index 0")


def add_arguments(sp):
    sp.add_argument("action", choices=("pack", "export", "preview"),
                    help="pack: folder -> file; export: file -> images + COCO; preview: one sample's labels as PNG")
    sp.add_argument("src", help="dataset folder (pack, preview) or packed file (export, preview)")
    sp.add_argument("dst", help="packed file (pack), output folder (export) or PNG (preview)")
    sp.add_argument("--index", type=int, default=0, help="sample to preview")
    sp.add_argument("--n-samples", type=int, default=512, help="samples per trace in the packed file")
    sp.add_argument("--image-height", type=int, default=256, help="image rows (export)")
    sp.add_argument("--regenerate", default=None, help="the command that regenerates the dataset (stored)")


def run(args):
    from gpr3d.simulation.packed import PackedDataset, load_sample, pack_dataset
    from gpr3d.viz.bscan import save_label_preview

    if args.action == "preview":
        _check_suffix(args.dst, (".png",), "dataset preview's output (dst)")
        survey, labels = load_sample(args.src, args.index)
        save_label_preview(survey, labels, args.dst)
        print(f"wrote {args.dst}")
    elif args.action == "pack":
        regen = args.regenerate or ""
        info = pack_dataset(args.src, args.dst, n_samples=args.n_samples, regenerate=regen)
        print(f"packed {info['n']} samples into {info['file']} ({info['bytes'] / 1e6:.1f} MB)")
    else:
        from gpr3d.io.resultdir import result_folder

        ds = PackedDataset(args.src)
        _out_folder(args.dst, "dataset export")
        with result_folder(args.dst, command="dataset export") as stage:  # all the images and coco.json, or none
            coco = ds.export_coco(stage, image_height=args.image_height)
        print(f"wrote {len(coco['images'])} images and {len(coco['annotations'])} boxes to {args.dst}/")
    return 0
