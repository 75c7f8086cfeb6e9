"""File formats, one module each: polygon meshes (OBJ, PLY, STL, OFF), point caches (MDD, PC2),
16-bit PNG, the model bundle, and scan sequences read from files.
"""
