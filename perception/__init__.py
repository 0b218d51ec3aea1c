"""perception: camera sources, target detection from images, and the ε centring test.

Import what you need from the submodules (`perception.stream_camera`, `perception.image_detector`,
`drone_inspect_core.centring`, ...); nothing heavy is imported here, and nothing here imports PyBullet.
"""
