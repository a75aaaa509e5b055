"""Secondary dynamics: features, networks F (removal) and H (synthesis), an actor's linear response, training, model files.

Arrays in, arrays out; PyTorch loads only when a name that needs it is first used.
"""
from facedyn.lazy_exports import lazy_exports

_PUBLIC = {
    "SUFFIXES": "modelfile", "describe_model": "modelfile", "load_model": "modelfile", "load_models": "modelfile",
    "save_blend": "modelfile", "save_model": "modelfile",
    "remove_dynamics": "removal",
    "CALIBRATION_EPOCHS": "synthesis_training", "EPOCHS": "synthesis_training", "calibrate_synthesis": "synthesis_training",
    "synthesis_config": "synthesis_training", "synthesize_dynamics": "synthesis", "train_synthesis": "synthesis_training",
    "TrainConfig": "training", "TrainingSequence": "training_sequence", "train_removal": "training",
    "MIN_ROWS": "response", "RIDGES": "response", "fit_linear_response": "response", "is_linear_response": "response",
    "remove_left_out": "response", "remove_with_response": "response", "response_template": "response",
    "settled_frames": "response",
    "align_trajectory": "root_motion", "delta_transfer": "root_motion", "skull_correspondence": "root_motion",
    "held_expression_spread": "diagnostics", "motion_left_beyond_sag": "diagnostics",
    "BandWeights": "bands", "BandWeightsFit": "bands",
    "FaceSetup": "face",
    "default_landmarks": "samples",
    "skull_accelerations": "skull_motion",
    "replace_spikes": "spikes",
}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
