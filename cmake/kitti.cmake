# Component: kitti (targets are added by the component's owner)
