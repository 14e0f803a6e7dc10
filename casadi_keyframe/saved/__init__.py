"""A saved run, one room: writing files whole (:mod:`.files`), a search's checkpoint
(:mod:`.checkpoint`), and a results folder written and read back checked (:mod:`.folder`)."""
from .checkpoint import Checkpoint, as_checkpoint
from .files import (FileDamaged, atomic_path, read_json, read_npz, writable_file,
                    writable_folder, write_json, write_npz)
from .folder import (CHECKPOINT, RESULT, SUMMARY, SavedRun, check_inputs, check_trajectory,
                     input_record, load_saved, read_run, run_file, save_result, saved_file)

__all__ = ["CHECKPOINT", "Checkpoint", "FileDamaged", "RESULT", "SUMMARY", "SavedRun",
           "as_checkpoint", "atomic_path", "check_inputs", "check_trajectory", "input_record", "load_saved", "read_json",
           "read_npz", "read_run", "run_file", "save_result", "saved_file", "writable_file",
           "writable_folder", "write_json", "write_npz"]
