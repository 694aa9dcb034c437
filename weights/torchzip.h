/* PyTorch zip checkpoints (what torch.save writes since PyTorch 1.6: .ckpt, .pt, .pth): a zip
 * archive whose entries are PREFIX/data.pkl (the pickled object, read by pickle.h), the
 * storages PREFIX/data/KEY, PREFIX/byteorder ("little" when present) and PREFIX/version.
 * torch.save stores every entry uncompressed (PyTorchStreamWriter, miniz with compression
 * level 0), so only STORED entries are read: a compressed entry is refused by name (a zip bomb
 * gets no further). The archive is read by runtime/zip.h: zip64 records (files over 4 GiB)
 * are read, every size and offset is checked against the file. The result is an
 * mx_safetensors whose tensors point into the mmapped archive, closed with mx_st_close. */
#ifndef MX_TORCHZIP_H
#define MX_TORCHZIP_H

#include <stddef.h>

#include "../runtime/status.h"
#include "safetensors.h"

/* Whether the first bytes are a zip local header ("PK\3\4"). */
int mx_torchzip_is_zip(const void *head, size_t n);

/* Opens the checkpoint; *skipped (may be NULL) receives the count of non-tensor entries of the
 * state dict. */
int mx_torchzip_open(mx_safetensors *f, const char *path, size_t *skipped, mx_status *st);

#endif
