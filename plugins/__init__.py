"""USD plugins shipped with facedyn (PXR_PLUGINPATH_NAME points at this folder)."""
